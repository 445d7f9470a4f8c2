"""The radius-parametric LP (docs/math/radius.md), dense, for HiGHS; and the evidence at a radius.

``max rho  s.t.  G x + c rho <= g,  lb <= x <= ub,  rho_min <= rho <= rho_max``: the margin form's
unit rows at ``rho = 0`` with ``t``'s column replaced by ``c`` (``sigma_{W_0}`` of the normalised row
where ``W`` enters). Its optimum is ``rho*(i, j, L)``. Every bound is explicit, so weak-duality
bounds stay rigorous, and none cuts off a feasible point at any ``rho >= 0``
(docs/math/radius.md#the-radius-lps-bounds). Each LP's rows are its record's
:class:`~tubejax.lp.declarations.formulation.RadiusForm`. The evidence for an edge at a radius is
the margin form's own at ``W = rho W_0``, not this LP's solution.
"""

from __future__ import annotations

import numpy as np

from .registry import FORMULATIONS, radius_forms
from ..engines.highs import solve_margin_lp
from ..declarations.formulation import Formulation, RadiusForm
from ..declarations.openloop_lp import OpenLoopLP
from ..declarations.tube_lp import TubeLP
from ...model.problem import TubeProblem
from ..declarations.radius_disturbance import rho_max_bound, unit_disturbance

__all__ = ["build_radius_lp", "radius_highs_optimum"]


def _radius(form: str | Formulation) -> RadiusForm:
    """The radius form of the LP ``form`` (a record, or its registered name: the record's ``radius``);
    ``ValueError`` naming those that have one otherwise."""
    f = form if isinstance(form, Formulation) else FORMULATIONS.get(form) if isinstance(form, str) else None
    if f is None or f.radius is None:
        raise ValueError(f"form: expected one of {radius_forms()}, got {form!r}")
    return f.radius


def build_radius_lp(problem: TubeProblem, W0=None, form: str | Formulation = "tube") -> TubeLP | OpenLoopLP:
    """The radius-parametric LP of ``problem`` (dense float64), solvable by
    :func:`~tubejax.lp.engines.highs.solve_margin_lp`.

    Parameters
    ----------
    problem : TubeProblem
        Its system's ``W`` only gives the default ``W0`` (its size is ignored).
    W0 : Ball or Polytope, optional
        The disturbance shape (default: :func:`unit_disturbance` of the system's ``W``, so
        that ``rho`` is in the user's units).
    form : {'tube', 'openloop'} or Formulation
        The LP: a record with a radius form, or its name.

    Returns
    -------
    TubeLP or OpenLoopLP
        ``G`` (unit rows), ``g`` at ``rho = 0``; ``t_coef`` the ``rho`` column ``c``, shape
        ``(n_rows,)``; ``t_min = rho_min``, ``t_max = rho_max``. The optimum ``t*`` is ``rho*``.
    """
    radius = _radius(form)
    W0 = unit_disturbance(problem.system.W)[0] if W0 is None else W0
    lp, c = radius.rows(problem, W0)
    rho_hi = rho_max_bound(problem.target, W0)
    x_ref = radius.reference(problem)
    slack = lp.g - lp.G @ x_ref
    soft = c > 0
    rho_ref = float(np.min(slack[soft] / c[soft])) if np.any(soft) else rho_hi
    return lp._replace(t_coef=c, t_max=rho_hi, t_min=min(rho_ref, 0.0) - rho_hi)


def radius_highs_optimum(problem: TubeProblem, form: str | Formulation = "tube", W0=None) -> tuple[float, object]:
    """``rho*`` of ``problem`` by HiGHS (simplex) on :func:`build_radius_lp`.

    Returns
    -------
    rho : float
        ``rho*`` (``-inf`` when the LP is infeasible: ``problem``'s rows without ``rho`` fail
        at every radius; ``nan`` on any other HiGHS failure)
    point : Tube or OpenLoopPlan or None
        HiGHS's solution (a tube at ``W = rho* W_0``, without stored-evidence status)
    """
    lp = build_radius_lp(problem, W0, form)
    res = solve_margin_lp(lp)
    if res.status == "Optimal":
        return res.margin, lp.index.split(res.x)
    return (-np.inf if res.status == "Infeasible" else np.nan), None
