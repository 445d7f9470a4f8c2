"""Sound necessary conditions that drop pairs and horizons before any solver.

Since ``0 in W``, a feasible tube at horizon ``L`` steers the ``w = 0``
trajectory from any ``x(0) in P_i`` into ``P_j`` at step ``L`` with inputs in
``U`` (Lemma 1). Hence:

* **target_too_small** -- ``P_j ⊖ W`` is empty (``Q_L ⊖ W`` must be non-empty and
  ``Q_L ⊆ P_j``): no edge into ``j`` at any ``L``.
* **obstacle_unreachable** -- obstacle case and ``P_j ∩ (A P_i ⊕ B U) = ∅``
  (``x(L-1) in P_i``): no ``L`` works.
* **free_unreachable** -- free case and ``P_j`` misses an outer bound of the
  nominal ``L``-step reachable set ``A^L P_i ⊕ (⊕_{t<L} A^t B U)``: that ``L`` is dropped.

Disjointness is shown by a separating direction ``d`` (from the facet normals
of both cells and the coordinate axes): ``sigma_R(d) < -sigma_{P_j}(-d)``.
That is only ever a proof of emptiness, so no feasible pair is pruned.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog

from .geometry import support
from .system import LinearSystem
from .workspace.decomposition import CellDecomposition

__all__ = ["PRUNE_REASONS", "prune_mask"]

PRUNE_REASONS = ("target_too_small", "obstacle_unreachable", "free_unreachable")

_SEP_TOL = 1e-9


def _target_fits(decomp: CellDecomposition, system: LinearSystem) -> np.ndarray:
    """Whether ``P_j ⊖ W`` is non-empty for each cell, shape ``(N,)``."""
    out = np.ones(decomp.n_cells, dtype=bool)
    for j, P in enumerate(decomp.cells):
        tight = P.h - support(system.W, P.H)
        res = linprog(np.zeros(P.dim), A_ub=P.H, b_ub=tight, bounds=[(None, None)] * P.dim,
                      method="highs")
        out[j] = res.status == 0
    return out


def prune_mask(decomp: CellDecomposition, system: LinearSystem, L_max: int):
    """Which ``(i, j, L)`` survive the necessary conditions.

    Returns
    -------
    keep : ndarray of bool, shape (N, N, L_max)
        ``keep[i, j, L-1]`` is False when horizon ``L`` of pair ``(i, j)`` is
        infeasible for sure (self-pairs are False too).
    counts : dict
        Number of pruned ``(pair, L)`` instances under each reason.
    """
    N, n = decomp.n_cells, decomp.dim
    A, B, U = system.A, system.B, system.U
    obst = decomp.obstacle_case_matrix()
    keep = np.ones((N, N, L_max), dtype=bool)
    keep[np.arange(N), np.arange(N), :] = False
    counts = {r: 0 for r in PRUNE_REASONS}

    fits = _target_fits(decomp, system)
    for j in np.flatnonzero(~fits):
        col = keep[:, j, :]
        counts["target_too_small"] += int(col.sum())
        keep[:, j, :] = False

    axes = np.vstack([np.eye(n), -np.eye(n)])
    Apow = [np.eye(n)]
    for _ in range(L_max):
        Apow.append(A @ Apow[-1])
    for i in range(N):
        Pi = decomp.cells[i]
        for j in range(N):
            if i == j or not keep[i, j].any():
                continue
            Pj = decomp.cells[j]
            D = np.vstack([Pj.H, -Pj.H, Pi.H, -Pi.H, axes])     # (n_d, n)
            lower_j = -Pj.support(-D)                          # min over P_j of d.x
            if obst[i, j]:
                reach = Pi.support(D @ A) + U.support(D @ B)   # sigma_{A P_i + B U}(d)
                if np.any(reach < lower_j - _SEP_TOL):
                    counts["obstacle_unreachable"] += int(keep[i, j].sum())
                    keep[i, j, :] = False
                continue
            acc = np.zeros(D.shape[0])                          # sum_{t<L} sigma_U(B^T (A^t)^T d)
            for L in range(1, L_max + 1):
                acc = acc + U.support(D @ Apow[L - 1] @ B)
                reach = Pi.support(D @ Apow[L]) + acc
                if keep[i, j, L - 1] and np.any(reach < lower_j - _SEP_TOL):
                    counts["free_unreachable"] += 1
                    keep[i, j, L - 1] = False
    return keep, counts
