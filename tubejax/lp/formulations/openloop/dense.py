"""The open-loop baseline (docs/math/open-loop.md; the paper's refs [10], [11]).

Each vertex ``v_{i,k}`` of the source cell gets its own input sequence
``u_k(0 .. L-1) in U``, fixed at time 0 (no feedback). The nominal
(``w = 0``) trajectory is

    ``xbar_k(l) = A^l v_{i,k} + sum_{t<l} A^{l-1-t} B u_k(t)``,

and the disturbance accumulated after ``l`` steps lies in
``D_l = W ⊕ A W ⊕ ... ⊕ A^{l-1} W`` with ``sigma_{D_l}(a) = sum_{t<l} sigma_W((A^t)^T a)``.
The constraints, per vertex ``k`` and facet row ``(a, b)`` of the set concerned, are

* ``a . xbar_k(l) <= b - sigma_{D_l}(a)`` for the facets of ``S``, ``l = 1 .. L-1``
  (``S = P_ij`` free case, ``S = P_i`` obstacle case; kind ``ROW_C2``);
* ``a . xbar_k(L) <= b - sigma_{D_L}(a)`` for the facets of ``P_j`` (kind ``ROW_C3``);
* ``u_k(l) in U`` (variable bounds for a box ``U``, hard rows ``G_hard`` otherwise).

By convexity (``xbar`` is affine in the initial state and the inputs are
interpolated with the same weights) the vertex sequences steer every
``x(0) in P_i``; this is the classical open-loop robust reachability test.

The problem container is :class:`tubejax.lp.formulations.tube.dense.TubeProblem` (its
``Z`` and ``eps_min`` are ignored), so the same :func:`tubejax.model.problem.pair_problem`
and :func:`tubejax.abstraction.build_abstraction` drive both methods.

Variables: ``u`` of shape ``(L, n_v, m)`` flattened row-major, plus the margin
``t`` appended by the solver. The LP has the field names of
:class:`~tubejax.lp.formulations.tube.dense.TubeLP`, so :func:`tubejax.lp.solvers.highs.solve_margin_lp`
solves it unchanged. Each margin row is divided by the length of its facet's normal, so
the margin is a state-space distance, as in the tube LP
(docs/math/margins.md#state-space-distances); a row with no input dependence (possible
only when ``H A^s B = 0``) is kept as a zero row ``0 . u + t <= g`` when
``g < 0`` (it makes the margin negative) and dropped when ``g >= 0`` (redundant).

A confirmed edge stores an :class:`OpenLoopPlan` (the input sequences) in
place of a :class:`~tubejax.lp.formulations.tube.dense.Tube`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ....model.geometry import support
from ..tube.dense import ROW_C2, ROW_C3, TubeProblem

__all__ = ["OpenLoopIndex", "OpenLoopPlan", "OpenLoopLP", "build_openloop_lp",
           "openloop_nominal", "openloop_violation", "disturbance_support"]


_ZERO_ROW = 1e-12


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


class OpenLoopLP(NamedTuple):
    """LP data of one open-loop problem (margin form, field names of ``TubeLP``).

    Attributes
    ----------
    G : ndarray, shape (n_rows, n_x)       unit rows (state constraints)
    g : ndarray, shape (n_rows,)
    row_kind : ndarray of int8, shape (n_rows,)   ``ROW_C2`` (safe set) / ``ROW_C3`` (target)
    G_hard : ndarray, shape (n_hard, n_x)   ``U`` rows for a non-box ``U`` (else 0 rows)
    g_hard : ndarray, shape (n_hard,)
    lb, ub : ndarray, shape (n_x,)          bounding box of ``U`` for every input
    t_max : float
    index : OpenLoopIndex
    t_coef : ndarray, shape (n_rows,), optional   ``t``'s column (``None``: all ones; see ``TubeLP``)
    t_min : float                                 lower bound on ``t`` (default ``-inf``)
    layout : None                                 (the tube LP's row layout; not declared here yet)
    """

    G: np.ndarray
    g: np.ndarray
    row_kind: np.ndarray
    G_hard: np.ndarray
    g_hard: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    t_max: float
    index: OpenLoopIndex
    t_coef: np.ndarray | None = None
    t_min: float = -np.inf
    layout: object = None


def _powers(A: np.ndarray, L: int) -> list[np.ndarray]:
    out = [np.eye(A.shape[0])]
    for _ in range(L):
        out.append(A @ out[-1])
    return out


def disturbance_support(system, H, L: int) -> np.ndarray:
    """``sigma_{D_l}(H)`` for ``l = 0 .. L``.

    Parameters
    ----------
    system : LinearSystem
    H : ndarray, shape (n_f, n)
        Directions.
    L : int

    Returns
    -------
    ndarray, shape (L + 1, n_f)
        Row ``l`` is ``sum_{t<l} sigma_W((A^t)^T H_f)`` (row 0 is zero).
    """
    H = np.asarray(H, float)
    Ap = _powers(system.A, L)
    out = np.zeros((L + 1, H.shape[0]))
    for t in range(L):
        out[t + 1] = out[t] + support(system.W, H @ Ap[t])
    return out


def build_openloop_lp(prob: TubeProblem, t_max: float = 1.0, scaling: str = "state") -> OpenLoopLP:
    """Assemble the margin-form open-loop LP of ``prob`` (dense float64).

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
    if not t_max > 0:
        raise ValueError(f"t_max must be > 0, got {t_max}")
    sysm = prob.system
    A, B = sysm.A, sysm.B
    m = sysm.m
    L = int(prob.L)
    V = prob.source.vertices                                   # (nv, n)
    nv = V.shape[0]
    ix = OpenLoopIndex(L, nv, m)
    Ap = _powers(A, L)
    rows, rhs, kinds, lengths = [], [], [], []
    sig_s = disturbance_support(sysm, prob.safe.H, L)         # (L+1, n_fs)
    sig_t = disturbance_support(sysm, prob.target.H, L)       # (L+1, n_ft)

    def add(H, h, sig, ell, kind):
        nf = H.shape[0]
        # coefficient of u_k(t) in H xbar_k(ell): H A^{ell-1-t} B, shape (ell, n_f, m)
        coef = np.stack([H @ Ap[ell - 1 - t] @ B for t in range(ell)])
        blk = np.zeros((nv, nf, L, nv, m))
        for k in range(nv):
            blk[k, :, :ell, k, :] = coef.transpose(1, 0, 2)
        rows.append(blk.reshape(nv * nf, ix.size))
        free = V @ Ap[ell].T @ H.T                              # (nv, n_f): H A^ell v_k
        rhs.append((h[None, :] - sig[ell][None, :] - free).ravel())
        kinds.append(np.full(nv * nf, kind, dtype=np.int8))
        lengths.append(np.tile(np.linalg.norm(H, axis=1), nv))     # the state-space normal of each row

    for ell in range(1, L):
        add(prob.safe.H, prob.safe.h, sig_s, ell, ROW_C2)
    add(prob.target.H, prob.target.h, sig_t, L, ROW_C3)
    G = np.vstack(rows)
    g = np.concatenate(rhs)
    kinds = np.concatenate(kinds)
    zero = np.linalg.norm(G, axis=1) <= _ZERO_ROW
    keep = ~zero | (g < 0)
    G, g, kinds, zero = G[keep], g[keep], kinds[keep], zero[keep]
    G[zero] = 0.0
    scale = (np.concatenate(lengths)[keep] if scaling == "state"
             else np.where(zero, 1.0, np.linalg.norm(G, axis=1)))
    G = G / scale[:, None]
    g = g / scale

    ulo, uhi = sysm.u_box()
    lb = np.tile(ulo, L * nv)
    ub = np.tile(uhi, L * nv)
    if sysm.u_is_box:
        G_hard = np.zeros((0, ix.size))
        g_hard = np.zeros(0)
    else:
        Hu, hu = sysm.U.H, sysm.U.h
        nu = Hu.shape[0]
        G_hard = np.zeros((L * nv * nu, ix.size))
        g_hard = np.tile(hu, L * nv)
        for ell in range(L):
            for k in range(nv):
                r0 = (ell * nv + k) * nu
                c0 = ix.u_col(ell, k, 0)
                G_hard[r0:r0 + nu, c0:c0 + m] = Hu
    return OpenLoopLP(G, g, kinds, G_hard, g_hard, lb, ub, float(t_max), ix)


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
    """Largest violation of the open-loop constraints by ``u``, in float64.

    Recomputed independently of :func:`build_openloop_lp`: the nominal
    trajectories are simulated forward (:func:`openloop_nominal`) and each
    vertex and step is checked against the unit facet rows of ``S``, ``P_j``
    (tightened by ``sigma_{D_l}``) and ``U``. A value ``<= 1e-9`` confirms the plan.

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
    x = openloop_nominal(prob, u)                              # (L+1, nv, n)
    viol = [(u @ sysm.U.H.T - sysm.U.h).ravel()]
    if L > 1:
        sig_s = disturbance_support(sysm, prob.safe.H, L - 1)  # (L, n_fs)
        c2 = x[1:L] @ prob.safe.H.T - prob.safe.h + sig_s[1:L, None, :]
        viol.append(c2.ravel())
    sig_t = disturbance_support(sysm, prob.target.H, L)[L]
    viol.append((x[L] @ prob.target.H.T - prob.target.h + sig_t).ravel())
    return float(max(0.0, max(np.max(v) for v in viol)))
