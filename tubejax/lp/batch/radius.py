"""The radius-parametric form of the tube and open-loop LPs (docs/math/radius.md).

With ``W = rho W_0`` the disturbance enters every LP linearly, so
``rho*(i, j, L) = max rho`` subject to Problem 2 (tube) or the open-loop constraints is one LP
of the margin form's shape, with the margin's all-ones ``t`` column replaced by ``rho``'s
per-row coefficients. Problem 2 at ``W = rho W_0`` is feasible iff ``rho <= rho*``; ``rho* < 0``
means infeasible even without disturbance.

``rho`` is in the user's units (:mod:`tubejax.lp.declarations.radius_disturbance`): a ball of radius ``r`` is ``rho = r``
times the unit ball, a cube of half-width ``h`` is ``rho = h`` times ``[-1, 1]^n``, any other
polytope ``W`` is ``rho = 1`` times itself.

Pieces, as for the other formulations, each reached through the LP's record
(``Formulation.radius``, a :class:`~tubejax.lp.declarations.radius_rows.RadiusForm`):

* :mod:`tubejax.lp.declarations.radius_rows` -- each LP's rows at ``rho = 0``, ``rho``'s column and
  its reference point;
* :mod:`tubejax.lp.evidence.radius_lp` -- :func:`~tubejax.lp.evidence.radius_lp.build_radius_lp` (HiGHS: the exact ``rho*``,
  :func:`~tubejax.lp.evidence.radius_lp.radius_highs_optimum`) and :func:`~tubejax.lp.evidence.radius_lp.radius_edge_verdict`, the stored
  evidence for an edge claimed at a radius (HiGHS's margin-form tube at that ``W``, re-checked
  in float64);
* the batched operators are the margin form's own (:mod:`tubejax.lp.declarations.tube_operator`,
  :mod:`tubejax.lp.declarations.openloop_operator`) in their ``'radius'`` form;
* :mod:`.radius_pdhg` -- :data:`~.radius_pdhg.RADIUS_TUBE_PDHG`, :data:`~.radius_pdhg.RADIUS_OPENLOOP_PDHG` for the
  one batched engine in its optimise mode (:func:`~.radius_pdhg.radius_pdhg_solver`,
  ``PdhgBatchSolver.optimise``): per instance an estimate of ``rho*``, a rigorous upper bound,
  a lower estimate, the status and the primal point.
"""

from ..evidence.radius_lp import build_radius_lp, radius_edge_verdict, radius_highs_optimum, radius_reference
from ..declarations.radius_disturbance import rho_max_bound, scaled_disturbance, unit_disturbance, with_disturbance
from .radius_pdhg import RADIUS_OPENLOOP_PDHG, RADIUS_OPTIONS, RADIUS_TUBE_PDHG, radius_pdhg_solver

__all__ = ["build_radius_lp", "radius_edge_verdict", "radius_highs_optimum", "radius_reference",
           "rho_max_bound", "scaled_disturbance", "unit_disturbance", "with_disturbance",
           "RADIUS_TUBE_PDHG", "RADIUS_OPENLOOP_PDHG", "RADIUS_OPTIONS", "radius_pdhg_solver"]
