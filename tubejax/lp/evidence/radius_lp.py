"""The radius-parametric LP (docs/math/radius.md), dense, for HiGHS; and the evidence at a radius.

With ``W = rho W_0`` (:mod:`~tubejax.lp.declarations.radius_disturbance`) every disturbance
term is linear in ``rho``: ``sigma_W = rho sigma_{W_0}`` in C4 of the tube LP, and
``sigma_{D_l} = rho sum_{t<l} sigma_{W_0}((A^t)^T .)`` in the open-loop rows. The LP

    ``max rho  s.t.  G x + c rho <= g,  lb <= x <= ub,  rho_min <= rho <= rho_max``

has the margin form's rows (``G``, ``g`` at ``rho = 0``, unit rows) with the margin's
all-ones ``t`` column replaced by ``c``: ``sigma_{W_0}`` of the normalised row where ``rho``
enters (tube: C4, ``c = sigma_{W_0}(-G[r, p_{l+1}])``, since that block is ``-H_z[r] / ||row||``;
open-loop: every row) and 0 elsewhere (tube C2 / C3). Its optimum is ``rho*(i, j, L)``:
Problem 2 at ``W = rho W_0`` is feasible iff ``rho <= rho*`` (the feasible sets shrink as
``rho`` grows, since ``c >= 0``).

Bounds, each explicit so that weak-duality bounds stay rigorous:

* ``x``: the margin form's bounds *without* the disturbance (``eps_l >= eps_min`` instead of
  ``width(W) / width(Z)``): they follow from C1-C3 alone, so they hold for every ``rho >= 0``
  and cut off no feasible point of Problem 2 at any radius;
* ``rho <= rho_max``: :func:`~tubejax.lp.declarations.radius_disturbance.rho_max_bound` of
  ``P_j`` (implied by C3 and C4, so it cuts off nothing either);
* ``rho >= rho_min = min(rho_ref, 0) - rho_max`` with ``rho_ref`` the radius at which a
  reference point ``x_ref`` satisfies every row (tube: ``p_l`` at the vertex mean of ``S``,
  ``p_L`` at that of ``P_j``, ``eps = eps_min``, ``u = 0``; open-loop: ``u = 0``). ``u = 0`` lies
  strictly inside every ``U`` (:class:`~tubejax.model.system.LinearSystem` requires it), so the
  reference also satisfies the hard rows of a non-box ``U``, which have no ``rho``. The LP is
  then always feasible and bounded, and ``rho_min`` is never binding. Below ``rho = 0`` the
  rows with ``c > 0`` are relaxed: ``rho* < 0`` means Problem 2 is infeasible even at
  ``W = {0}``, and a dual bound ``< 0`` certifies it (the bounds on ``x`` hold at ``rho = 0``).

The evidence for an edge claimed at a radius ``rho`` is not this LP's solution but, as
everywhere, HiGHS's margin-form solution at ``W = rho W_0`` re-checked by the method's own
float64 checker (:func:`radius_edge_verdict`).
"""

from __future__ import annotations

import numpy as np

from ...model.geometry import Ball, support
from .verdict import Verdict, highs_verdict
from ..engines.highs import solve_margin_lp
from ..declarations.openloop_lp import OpenLoopIndex, OpenLoopLP
from ..declarations.openloop_families import OPENLOOP_FAMILIES, float_plan_terms, plan_identity
from ..declarations.tube_lp import TubeIndex, TubeLP, build_tube_lp, row_kinds
from ...model.problem import TubeProblem
from ..declarations.tube_families import TUBE_FAMILIES, float_terms
from ..declarations.row_families import dense_rhs, dense_rows, families_in, kept_rows, state_lengths, zero_rows
from ..declarations.radius_disturbance import rho_max_bound, scaled_disturbance, unit_disturbance, with_disturbance

__all__ = ["FORMS", "build_radius_lp", "radius_reference", "radius_highs_optimum", "radius_edge_verdict"]

#: The LPs that have a radius form.
FORMS = ("tube", "openloop")


def _check_form(form: str) -> None:
    if form not in FORMS:
        raise ValueError(f"form: expected one of {FORMS}, got {form!r}")


def radius_reference(problem: TubeProblem, form: str = "tube") -> np.ndarray:
    """The reference point ``x_ref`` (see the module docstring), shape ``(n_x,)``."""
    _check_form(form)
    sysm, L = problem.system, int(problem.L)
    if form == "openloop":
        return np.zeros(OpenLoopIndex(L, problem.source.n_vertices, sysm.m).size)
    ix = TubeIndex(L, sysm.n, problem.source.n_vertices, sysm.m)
    p = np.repeat(problem.safe.vertices.mean(axis=0)[None], L, axis=0)
    p[L - 1] = problem.target.vertices.mean(axis=0)
    x = np.zeros(ix.size)
    x[ix.p] = p.ravel()
    x[ix.eps] = float(problem.eps_min)
    return x


def _tube_rows(problem: TubeProblem, W0):
    """Rows at ``rho = 0`` (``W = {0}``: rhs and bounds without the disturbance) and ``c``: in the
    rows of each family that ``sigma_W`` enters (:attr:`~tubejax.lp.declarations.row_families.RowFamily.disturbed`: C4),
    ``sigma_{W_0}`` of the row's unit state-space normal, found by the family's name."""
    free = with_disturbance(problem, Ball(problem.system.n, 0.0))
    lp, d = build_tube_lp(free), float_terms(free)
    c = np.zeros(lp.G.shape[0])
    for f in families_in(TUBE_FAMILIES, d):
        if f.disturbed and f.name in lp.layout.names:
            unit = f.normals(d) / np.linalg.norm(f.normals(d), axis=1)[:, None]      # as the LP's rows
            c[lp.layout.slice(f.name)] = np.broadcast_to(support(W0, unit), lp.layout.shape(f.name)).ravel()
    return lp, c


def _openloop_rows(problem: TubeProblem, W0):
    """The open-loop rows (:data:`~tubejax.lp.declarations.openloop_families.OPENLOOP_FAMILIES`,
    ``build_openloop_lp``'s order) at ``rho = 0``, and ``c``: the right-hand sides at ``rho = 0``
    less those at ``W = W0`` (``sigma_{D_l}`` of ``W0``, row by row).

    A row without input dependence is ``c rho <= g``, kept by the zero-row rule
    (:func:`~tubejax.lp.declarations.row_families.kept_rows`). Rows are divided by the length of
    their facet's normal, as ``build_openloop_lp`` does.
    """
    sysm = problem.system
    L, m = int(problem.L), sysm.m
    ix = OpenLoopIndex(L, problem.source.n_vertices, m)
    d0 = float_plan_terms(problem, W=None)
    G, g, layout = dense_rows(d0, m, "margin", sysm.u_is_box, OPENLOOP_FAMILIES, plan_identity)
    c = g - dense_rhs(float_plan_terms(problem, W=W0), "margin", sysm.u_is_box, OPENLOOP_FAMILIES)
    lengths = state_lengths(d0, "margin", sysm.u_is_box, lambda H: np.linalg.norm(H, axis=1), OPENLOOP_FAMILIES)
    kinds = row_kinds(layout)
    zero = zero_rows(G)
    keep = kept_rows(zero, g, c)
    G, g, c, kinds, zero, scale = G[keep], g[keep], c[keep], kinds[keep], zero[keep], lengths[keep]
    G[zero] = 0.0
    ulo, uhi = sysm.u_box()
    G_hard, g_hard, _ = dense_rows(d0, m, "hard", sysm.u_is_box, OPENLOOP_FAMILIES, plan_identity)
    lp = OpenLoopLP(G / scale[:, None], g / scale, kinds, G_hard, g_hard, np.tile(ulo, L * ix.n_v),
                    np.tile(uhi, L * ix.n_v), 1.0, ix)
    return lp, c / scale


def build_radius_lp(problem: TubeProblem, W0=None, form: str = "tube") -> TubeLP | OpenLoopLP:
    """The radius-parametric LP of ``problem`` (dense float64), solvable by
    :func:`~tubejax.lp.engines.highs.solve_margin_lp`.

    Parameters
    ----------
    problem : TubeProblem
        Its system's ``W`` only gives the default ``W0`` (its size is ignored).
    W0 : Ball or Polytope, optional
        The disturbance shape (default: :func:`unit_disturbance` of the system's ``W``, so
        that ``rho`` is in the user's units).
    form : {'tube', 'openloop'}

    Returns
    -------
    TubeLP or OpenLoopLP
        ``G`` (unit rows), ``g`` at ``rho = 0``; ``t_coef`` the ``rho`` column ``c``, shape
        ``(n_rows,)``; ``t_min = rho_min``, ``t_max = rho_max``. The optimum ``t*`` is ``rho*``.
    """
    _check_form(form)
    W0 = unit_disturbance(problem.system.W)[0] if W0 is None else W0
    lp, c = (_tube_rows if form == "tube" else _openloop_rows)(problem, W0)
    rho_hi = rho_max_bound(problem.target, W0)
    x_ref = radius_reference(problem, form)
    slack = lp.g - lp.G @ x_ref
    soft = c > 0
    rho_ref = float(np.min(slack[soft] / c[soft])) if np.any(soft) else rho_hi
    return lp._replace(t_coef=c, t_max=rho_hi, t_min=min(rho_ref, 0.0) - rho_hi)


def radius_highs_optimum(problem: TubeProblem, form: str = "tube", W0=None) -> tuple[float, object]:
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


def radius_edge_verdict(problem: TubeProblem, W0, rho: float, form: str = "tube",
                        provenance: str = "highs") -> Verdict:
    """The stored evidence for an edge claimed at radius ``rho``: HiGHS solves the margin form
    of Problem 2 at ``W = rho W0`` and its tube (open-loop: plan) is re-checked in float64 by
    ``tube_violation`` (``openloop_violation``) at that ``W`` (docs/math/evidence.md).

    Parameters
    ----------
    problem : TubeProblem      (its own ``W`` is replaced)
    W0 : Ball or Polytope, or None (then :func:`unit_disturbance` of the system's ``W``)
    rho : float, ``>= 0``
    form : {'tube', 'openloop'}

    Returns
    -------
    Verdict
        ``'edge'`` with the checked tube / plan, ``'infeasible'`` or ``'unconfirmed'``.
    """
    _check_form(form)
    W0 = unit_disturbance(problem.system.W)[0] if W0 is None else W0
    at_rho = with_disturbance(problem, scaled_disturbance(W0, rho))
    return highs_verdict(at_rho, provenance, form=form)
