"""Candidate instances ``(i, j, L)`` of Algorithm 2, found without any all-pairs step.

A feasible ``(i, j, L)`` has ``x(L) in A^L P_i ⊕ R_L`` (``R_L = ⊕_{t<L} A^t B U``, Lemma 1 with
``w = 0``) and ``x(L) in P_j ⊖ W``, so the box of ``P_j ⊖ W`` meets the bounding box of
``A^L P_i ⊕ R_L`` for some ``L <= L_max``, hence the bounding box of their union over ``L``.
:func:`candidate_pairs` finds those pairs with a ``cKDTree`` over the target box centres
(Chebyshev balls in axis-scaled coordinates, then the exact box test): cost grows with the pairs
returned, not ``N^2``. :func:`build_candidates` then prunes (:mod:`tubejax.abstraction.pruning`),
tests the survivors' obstacle case and drops obstacle-case pairs that fail condition (O)
(docs/math/evidence.md#why-pruning-is-sound); all as sparse arrays over the surviving pairs.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .pruning import PRUNE_REASONS, prune_pairs, reach_tables, target_fits
from .safe_reach import constrained_reach
from .vertex_lp import VERTEX_LP_MIN_DIM, vertex_lp_keep
from ..model.system import LinearSystem
from ..model.workspace.decomposition import CellDecomposition
from ..lp.engines.workers import helper_counts, shared_process_workers

__all__ = ["Candidates", "all_pairs", "candidate_pairs", "build_candidates"]


@dataclass
class Candidates:
    """The instances a run of Algorithm 2 solves.

    Attributes
    ----------
    src, dst : ndarray of int, shape (K,)
        Pairs with at least one horizon left, sorted by ``(src, dst)``.
    keep : ndarray of bool, shape (K, L_max)
        ``keep[k, L-1]``: horizon ``L`` of pair ``k`` is solved (unless an edge is found earlier).
    obstacle : ndarray of bool, shape (K,)
        The obstacle case of each pair (docs/math/problem-data.md).
    pruned : dict
        Instances dropped under each reason of :data:`tubejax.abstraction.pruning.PRUNE_REASONS`.
    stats : dict
        Pair counts and the seconds of each step.
    """

    src: np.ndarray
    dst: np.ndarray
    keep: np.ndarray
    obstacle: np.ndarray
    pruned: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)

    @property
    def n_instances(self) -> int:
        return int(self.keep.sum())


def all_pairs(N: int) -> tuple[np.ndarray, np.ndarray]:
    """Every ordered pair ``i != j`` as two arrays of shape ``(N (N-1),)``, sorted."""
    src = np.repeat(np.arange(N), N - 1)
    d = np.tile(np.arange(N - 1), N)
    return src, d + (d >= src)


def candidate_pairs(reach_lo, reach_hi, target_lo, target_hi, targets, tol: float = 0.0):
    """Pairs ``(i, j)``, ``i != j``, whose boxes meet (within ``tol``), via a k-d tree.

    Parameters
    ----------
    reach_lo, reach_hi : ndarray, shape (N, n)
        Box of everything cell ``i`` may reach.
    target_lo, target_hi : ndarray, shape (N, n)
        Box of each target (only rows in ``targets`` are used).
    targets : ndarray of int, shape (M,)
        Cells that may be targets.

    Returns
    -------
    src, dst : ndarray of int, shape (K,), sorted by ``(src, dst)``
    """
    targets = np.asarray(targets, dtype=int)
    N = len(reach_lo)
    if len(targets) == 0 or N == 0:
        return np.zeros(0, int), np.zeros(0, int)
    t_lo, t_hi = target_lo[targets], target_hi[targets]
    scale = np.maximum(np.max(t_hi - t_lo, axis=0) / 2, 1e-12)                 # (n,)
    centre = (t_lo + t_hi) / 2 / scale
    tree = cKDTree(centre)
    q_centre = (reach_lo + reach_hi) / 2 / scale
    radius = np.max((reach_hi - reach_lo) / 2 / scale, axis=1) + 1.0 + tol / scale.min()
    hits = tree.query_ball_point(q_centre, radius * (1 + 1e-12), p=np.inf)
    counts = np.fromiter((len(h) for h in hits), dtype=int, count=N)
    src = np.repeat(np.arange(N), counts)
    dst = targets[np.fromiter((k for h in hits for k in h), dtype=int, count=int(counts.sum()))]
    ok = (src != dst) & np.all((reach_lo[src] <= target_hi[dst] + tol) & (target_lo[dst] <= reach_hi[src] + tol),
                               axis=1)
    src, dst = src[ok], dst[ok]
    order = np.lexsort((dst, src))
    return src[order], dst[order]


def _helpers():
    """The shared HiGHS helper processes when the machine has a core to spare, else None."""
    return shared_process_workers() if sum(helper_counts()) > 1 else None


def build_candidates(decomp: CellDecomposition, system: LinearSystem, L_max: int,
                     pruning: bool = True, *, vertex_lp: bool = True) -> Candidates:
    """The pairs and horizons to solve, with the obstacle case of each pair. ``pruning=False`` keeps every
    ordered pair and horizon (the all-pairs reference). From ``VERTEX_LP_MIN_DIM`` dimensions the vertex
    LPs of :mod:`tubejax.abstraction.vertex_lp` run last; ``vertex_lp=False`` leaves them out (a superset)."""
    N = decomp.n_cells
    pruned = {r: 0 for r in PRUNE_REASONS}
    t0 = time.perf_counter()
    if not pruning:
        src, dst = all_pairs(N)
        obstacle = decomp.obstacle_cases(src, dst)
        keep = np.ones((len(src), L_max), dtype=bool)
        stats = {"n_candidate_pairs": len(src), "n_obstacle_case_candidates": int(obstacle.sum()),
                 "seconds_obstacle_case": time.perf_counter() - t0}
        return Candidates(src, dst, keep, obstacle, pruned, stats)
    T = reach_tables(decomp, system, L_max)
    fits = target_fits(decomp, system)
    t1 = time.perf_counter()
    n_unfit = int(N - fits.sum())
    pruned["target_too_small"] = n_unfit * (N - 1) * L_max
    ax_p, ax_n = T.axes[:decomp.dim], T.axes[decomp.dim:]
    hi = T.cell[:, 1:, ax_p] + T.inputs[None, 1:, ax_p]                           # (N, L, n)
    lo = -(T.cell[:, 1:, ax_n] + T.inputs[None, 1:, ax_n])
    src, dst = candidate_pairs(lo.min(axis=1), hi.max(axis=1), -T.target[:, ax_n], T.target[:, ax_p],
                               np.flatnonzero(fits), tol=float(T.tol[-1]))
    n_cand = len(src)
    pruned["outside_reach"] = (N * (N - 1) - n_unfit * (N - 1) - n_cand) * L_max
    t2 = time.perf_counter()
    keep, reach1, counts = prune_pairs(decomp, system, T, src, dst)
    pruned.update(counts)
    alive = keep.any(axis=1)
    src, dst, keep, reach1 = src[alive], dst[alive], keep[alive], reach1[alive]
    t3 = time.perf_counter()
    obstacle = decomp.obstacle_cases(src, dst)
    t4 = time.perf_counter()
    n_tested, n_obst = len(src), int(obstacle.sum())
    dead = obstacle & ~reach1                                                     # condition (O) fails
    pruned["obstacle_unreachable"] = int(keep[dead].sum())
    keep[dead] = False
    alive = keep.any(axis=1)
    src, dst, keep, obstacle = src[alive], dst[alive], keep[alive], obstacle[alive]
    t5 = time.perf_counter()
    ok = constrained_reach(decomp, system, T, src, dst, obstacle, keep=keep)
    pruned["safe_set_unreachable"] = int((keep & ~ok).sum())
    keep &= ok
    n_vlp = n_reused = n_witnessed = 0
    t_vlp = time.perf_counter()
    if vertex_lp and decomp.dim >= VERTEX_LP_MIN_DIM:
        alive = keep.any(axis=1)
        src, dst, keep, obstacle = src[alive], dst[alive], keep[alive], obstacle[alive]
        keep, pruned["vertex_lp_infeasible"], n_vlp, n_reused, n_witnessed = vertex_lp_keep(
            decomp, system, T, src, dst, obstacle, keep, workers=_helpers())
    t6 = time.perf_counter()
    alive = keep.any(axis=1)
    stats = {"n_candidate_pairs": n_cand, "n_tested_pairs": n_tested,
             "n_obstacle_case_candidates": n_obst, "n_free_case_candidates": n_tested - n_obst,
             "n_directions": len(T.D), "n_vertex_lps": n_vlp,
             "n_vertex_duals_reused": n_reused, "n_vertex_lps_witnessed": n_witnessed,
             "seconds_tables": t1 - t0, "seconds_spatial_index": t2 - t1,
             "seconds_prune": t3 - t2 + t6 - t5, "seconds_vertex_lp": t6 - t_vlp,
             "seconds_obstacle_case": t4 - t3}
    return Candidates(src[alive], dst[alive], keep[alive], obstacle[alive], pruned, stats)
