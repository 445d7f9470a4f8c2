"""Evidence: what makes a verdict trustworthy (docs/math/evidence.md).

* :mod:`tubejax.lp.engines.certify` -- float64 weak-duality certificates of the batched solver;
* :mod:`.verdict` -- verdicts, and the HiGHS confirmation of every edge;

and the exact (rational) proofs on top ("Proof levels"):

* :mod:`.rational` -- rational arrays and the rationalisation rules;
* :mod:`.exact_geometry` -- exact facets and support functions of polytopes;
* :mod:`.exact_problem` -- the rational data of a tube problem (outward-rounded ``sigma_W`` of a ball);
* :mod:`.check` -- exact checkers of tubes and open-loop plans (:mod:`.check_batch`: many at once);
* :mod:`.basis`, :mod:`.rows` -- an exact vertex from HiGHS's optimal basis;
* :mod:`.prove` -- proof levels;
* :mod:`.safe_set` -- exact proofs that a safe set avoids the obstacles' interiors.
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
