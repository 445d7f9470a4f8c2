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

Disjointness is shown by a separating direction ``d`` (any facet normal of any
cell, either sign, or a coordinate axis): ``sigma_R(d) < -sigma_{P_j}(-d)``.
That is only ever a proof of emptiness, so no feasible pair is pruned.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog

from .geometry import support
from .system import LinearSystem
from .workspace.decomposition import CellDecomposition

__all__ = ["PRUNE_REASONS", "prune_mask", "separating_directions"]

PRUNE_REASONS = ("target_too_small", "obstacle_unreachable", "free_unreachable")

_SEP_TOL = 1e-9


def _target_fits(decomp: CellDecomposition, system: LinearSystem) -> np.ndarray:
    """Whether ``P_j ⊖ W`` is non-empty for each cell, shape ``(N,)``.

    One LP per distinct cell shape up to translation (a grid map has one).
    """
    out = np.ones(decomp.n_cells, dtype=bool)
    seen = {}
    for j, P in enumerate(decomp.cells):
        c = P.vertices.mean(axis=0)
        key = (np.round(P.H, 12).tobytes(), np.round(P.h - P.H @ c, 12).tobytes())
        if key not in seen:
            tight = P.h - support(system.W, P.H)
            res = linprog(np.zeros(P.dim), A_ub=P.H, b_ub=tight, bounds=[(None, None)] * P.dim,
                          method="highs")
            seen[key] = res.status == 0
        out[j] = seen[key]
    return out


def separating_directions(decomp: CellDecomposition) -> np.ndarray:
    """All distinct facet normals of all cells, both signs, and the coordinate axes, shape ``(n_d, n)``."""
    n = decomp.dim
    D = np.vstack([c.H for c in decomp.cells] + [-c.H for c in decomp.cells]
                  + [np.eye(n), -np.eye(n)])
    return np.unique(np.round(D, 12), axis=0)


def prune_mask(decomp: CellDecomposition, system: LinearSystem, L_max: int, chunk: int = 256):
    """Which ``(i, j, L)`` survive the necessary conditions.

    A pair (horizon) is dropped when some direction ``d`` of
    :func:`separating_directions` separates ``P_j`` from the nominal reachable
    set; support values are computed once per cell and direction, so the cost
    is ``O(N^2 n_d)`` comparisons per horizon.

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
    counts["target_too_small"] = int(keep[:, ~fits, :].sum())
    keep[:, ~fits, :] = False

    D = separating_directions(decomp)                                      # (n_d, n)
    lower = np.stack([-c.support(-D) for c in decomp.cells])              # min over P_j of d.x, (N, n_d)
    Apow = [np.eye(n)]
    for _ in range(L_max):
        Apow.append(A @ Apow[-1])

    def sigma_cells(M):                                                    # max over P_i of (d M).x, (N, n_d)
        return np.stack([c.support(D @ M) for c in decomp.cells])

    su = [U.support(D @ Apow[t] @ B) for t in range(L_max)]               # sigma_U(B^T (A^t)^T d), (n_d,)
    one_step = sigma_cells(A) + su[0]                                      # A P_i + B U
    reach = []
    acc = np.zeros(len(D))
    for L in range(1, L_max + 1):
        acc = acc + su[L - 1]
        reach.append(sigma_cells(Apow[L]) + acc)                           # A^L P_i + sum A^t B U
    for i0 in range(0, N, chunk):
        I = slice(i0, min(N, i0 + chunk))

        def separated(R):                                                  # (ci, N)
            return np.any(R[I, None, :] < lower[None, :, :] - _SEP_TOL, axis=2)

        blk = keep[I]
        ob = obst[I]
        dead = ob & separated(one_step)
        counts["obstacle_unreachable"] += int(blk[dead].sum())
        blk[dead] = False
        for L in range(1, L_max + 1):
            cut = ~ob & blk[:, :, L - 1] & separated(reach[L - 1])
            counts["free_unreachable"] += int(cut.sum())
            blk[:, :, L - 1] &= ~cut
        keep[I] = blk
    return keep, counts
