"""Evidence: what makes a verdict trustworthy (docs/math/evidence.md): verdicts and their HiGHS
confirmation (:mod:`.verdict`), rational data (:mod:`.rational`, :mod:`.exact_geometry`,
:mod:`.exact_problem`), exact checks and proofs (:mod:`.check`, :mod:`.basis`, :mod:`.prove`,
:mod:`.decide`, :mod:`.safe_set`) and the LP records (:mod:`.registry`).
"""

from .check import ExactPlan, ExactTube, exact_openloop_violation, exact_tube_violation
from .exact_geometry import ExactGeometryError, exact_hull
from .prove import PROOF_LEVELS, Proof, prove_evidence, prove_with_basis, settle
from .rational import QArray, binary_rational, decimal_rational, sqrt_upper

__all__ = [
    "ExactGeometryError", "ExactPlan", "ExactTube", "PROOF_LEVELS", "Proof", "QArray",
    "binary_rational", "decimal_rational", "exact_hull", "exact_openloop_violation",
    "exact_tube_violation", "prove_evidence", "prove_with_basis",
    "settle", "sqrt_upper",
]
