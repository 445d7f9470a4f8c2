"""The open-loop baseline's dense LP for HiGHS (docs/math/open-loop.md; the paper's refs [10], [11]).

Each vertex of the source cell gets its own input sequence ``u_k(0 .. L-1) in U``, fixed at time 0;
the rows are :data:`~.openloop_families.OPENLOOP_FAMILIES`'. The problem is a
:class:`~tubejax.model.problem.TubeProblem` (``Z`` and ``eps_min`` ignored) and the LP has the fields
of :class:`~tubejax.lp.declarations.tube_lp.TubeLP`, so pair problems, pruning and
:func:`~tubejax.lp.engines.highs.solve_margin_lp` serve both methods. Margin rows are state-space
distances (docs/math/margins.md). A confirmed edge stores an :class:`OpenLoopPlan`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .tube_lp import TubeLP, row_kinds, worst_residual
from .tube_variables import input_bounds
from ...model.problem import TubeProblem
from .row_families import dense_rhs, dense_rows, state_lengths, zero_row_rule
from .openloop_families import OPENLOOP_FAMILIES, PlanVars, float_plan_terms, plan_identity, plan_residuals

__all__ = ["OpenLoopIndex", "OpenLoopPlan", "OpenLoopLP", "build_openloop_lp", "openloop_lp_column",
           "openloop_nominal", "openloop_violation"]


class OpenLoopPlan(NamedTuple):
    """The evidence of an open-loop edge: ``u`` of shape ``(L, n_v, m)``.

    ``u[l, k]`` is the input applied at step ``l`` to the trajectory that
    starts at vertex ``k`` of the source cell (canonical vertex order).
    """

    u: np.ndarray

    def states(self, prob: TubeProblem) -> np.ndarray:
        """Nominal states ``xbar_k(l)``, shape ``(L + 1, n_v, n)`` (see :func:`openloop_nominal`)."""
        return openloop_nominal(prob, self.u)


class OpenLoopIndex(NamedTuple):
    """Layout of the variable vector ``x = vec(u)``, ``u`` of shape ``(L, n_v, m)``."""

    L: int
    n_v: int
    m: int

    @property
    def size(self) -> int:
        return self.L * self.n_v * self.m

    @property
    def u(self) -> slice:
        return slice(0, self.size)

    def u_col(self, ell: int, k: int, d: int) -> int:
        """Column of ``u_k(ell)[d]``, ``ell = 0..L-1``."""
        return (ell * self.n_v + k) * self.m + d

    def split(self, x) -> OpenLoopPlan:
        """``x`` of shape ``(size,)`` (a trailing ``t`` is ignored) -> :class:`OpenLoopPlan`."""
        x = np.asarray(x, float)
        return OpenLoopPlan(x[: self.size].reshape(self.L, self.n_v, self.m).copy())

    def pack(self, plan: OpenLoopPlan) -> np.ndarray:
        """:class:`OpenLoopPlan` -> ``x`` of shape ``(size,)``."""
        return np.ravel(np.asarray(plan.u, float)).copy()


class OpenLoopLP(TubeLP):
    """LP data of one open-loop problem: the fields of :class:`~.tube_lp.TubeLP` (its own type, so that
    the registry tells the LPs apart), ``index`` an :class:`OpenLoopIndex`, ``row_kind`` ``ROW_C2`` (safe
    set) / ``ROW_C3`` (target), ``lb``, ``ub`` the bounding box of ``U`` for every input, no ``layout``."""

    __slots__ = ()


def build_openloop_lp(prob: TubeProblem, t_max: float = 1.0, scaling: str = "state") -> OpenLoopLP:
    """Assemble the margin-form open-loop LP of ``prob`` (dense float64) from its row families
    (:data:`~.openloop_families.OPENLOOP_FAMILIES`: ``safe`` then ``target``, each ``(steps, n_v, f)``).

    Parameters
    ----------
    prob : TubeProblem
        Uses ``system``, ``source``, ``target``, ``safe`` and ``L``; ``Z`` is ignored.
    t_max : float
        Upper bound on the margin, ``> 0``.
    scaling : {'state', 'coefficients'}
        Each row per unit of its facet's normal (a state-space distance), or, as transition
        files before format 3 did, per unit of its coefficients over the inputs.

    Returns
    -------
    OpenLoopLP
    """
    return openloop_lp_column(prob, None, t_max, scaling)[0]


def openloop_lp_column(prob: TubeProblem, W0=None, t_max: float = 1.0,
                       scaling: str = "state") -> tuple[OpenLoopLP, np.ndarray | None]:
    """:func:`build_openloop_lp`, or with ``W0`` its radius form (docs/math/radius.md): the rows at
    ``rho = 0`` (no ``sigma_D``) and ``rho``'s column ``c``, shape ``(n_rows,)``: the right-hand sides
    at ``rho = 0`` less those at ``W = W0``, per unit row (``None`` without ``W0``). A row without
    input dependence (``c rho <= g`` in the radius form) stays by :func:`~.row_families.zero_row_rule`.
    """
    if not t_max > 0:
        raise ValueError(f"t_max must be > 0, got {t_max}")
    sysm = prob.system
    L, m = int(prob.L), sysm.m
    ix = OpenLoopIndex(L, prob.source.n_vertices, m)
    d = float_plan_terms(prob, W="system" if W0 is None else None)
    G, g, layout = dense_rows(d, m, "margin", sysm.u_is_box, OPENLOOP_FAMILIES, plan_identity)
    c = None if W0 is None else g - dense_rhs(float_plan_terms(prob, W=W0), "margin", sysm.u_is_box,
                                              OPENLOOP_FAMILIES)
    lengths = state_lengths(d, "margin", sysm.u_is_box, lambda H: np.linalg.norm(H, axis=1), OPENLOOP_FAMILIES)
    zero, keep, G = zero_row_rule(G, g, c)
    G, g, kinds, zero = G[keep], g[keep], row_kinds(layout)[keep], zero[keep]
    scale = lengths[keep] if scaling == "state" else np.where(zero, 1.0, np.linalg.norm(G, axis=1))
    G_hard, g_hard, _ = dense_rows(d, m, "hard", sysm.u_is_box, OPENLOOP_FAMILIES, plan_identity)
    lp = OpenLoopLP(G / scale[:, None], g / scale, kinds, G_hard, g_hard, *input_bounds(ix, sysm.u_box()),
                    float(t_max), ix)
    return lp, None if c is None else c[keep] / scale


def openloop_nominal(prob: TubeProblem, u) -> np.ndarray:
    """Nominal vertex trajectories by forward simulation with ``w = 0``.

    Parameters
    ----------
    prob : TubeProblem
    u : array_like, shape (L, n_v, m)

    Returns
    -------
    ndarray, shape (L + 1, n_v, n)
        ``xbar[l, k]``; ``xbar[0]`` is the source cell's vertices.
    """
    sysm = prob.system
    u = np.asarray(u, float)
    x = [np.asarray(prob.source.vertices, float)]
    for ell in range(u.shape[0]):
        x.append(x[-1] @ sysm.A.T + u[ell] @ sysm.B.T)
    return np.stack(x)


def openloop_violation(prob: TubeProblem, u) -> float:
    """Largest violation of the open-loop constraints by ``u``, in float64: the residuals of
    :func:`~.openloop_families.plan_residuals`, each per unit of its normal. ``<= 1e-9`` confirms the plan.

    Parameters
    ----------
    prob : TubeProblem
    u : array_like, shape (L, n_v, m), or an :class:`OpenLoopPlan`

    Returns
    -------
    float
        ``max(0, ...)`` of all violations (a state-space distance for the
        state rows); ``inf`` for a wrong shape or non-finite values.
    """
    if isinstance(u, OpenLoopPlan):
        u = u.u
    sysm = prob.system
    L, nv, m = int(prob.L), prob.source.n_vertices, sysm.m
    u = np.asarray(u, float)
    if u.shape != (L, nv, m) or not np.all(np.isfinite(u)):
        return float("inf")
    return float(max(0.0, worst_residual(plan_residuals(float_plan_terms(prob), PlanVars(u)))))
