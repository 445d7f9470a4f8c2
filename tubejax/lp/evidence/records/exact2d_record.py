"""The exact polygon computation (``exact2d``): a method without an LP, so without row families.

It declares no family over a state constraint, so it refuses a system with one
(:func:`~tubejax.lp.evidence.registry.check_state_constraints`); its solver is
:data:`~tubejax.reachability.exact2d.exact2d_solve_batch`.
"""

from __future__ import annotations

from ...declarations.formulation import Formulation
from . import SeriesStyle

__all__ = ["FORMULATION", "STYLE"]

FORMULATION = Formulation("exact2d", (), rank=2, provenance="exact2d", dimensions=(2,),
                          exact_reference=True)
#: How the plots draw its series (:func:`~tubejax.lp.evidence.registry.series_style`).
STYLE = SeriesStyle("#000000", "--", "s")       # black: the most any feedback can achieve
