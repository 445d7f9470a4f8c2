"""Algorithm 2: every ordered pair x horizon -> a verified transition system.

Horizons run in rounds ``L = 1, 2, ..., L_max``; in each round every pair
still without an edge (and not pruned at that ``L``) is handed to a batch
solver; a pair found feasible at ``L`` leaves the later rounds, so its edge
cost is the minimal ``L`` (SPEC section 2, slip 2). A batched solver may let the
HiGHS confirmations of likely edges run on into later rounds (``Pending``). A solver returns one
:class:`Verdict` per problem; only ``status == 'edge'`` verdicts, whose tube
passed :func:`tube_violation` ``<= 1e-9``, enter the transition system.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from typing import Callable

import numpy as np
from tqdm.auto import tqdm

from .lp.evidence.verdict import Pending, Verdict, highs_solve_batch
from .lp.formulations.zshape import make_z
from .problem import pair_problem
from .pruning import PRUNE_REASONS, prune_mask
from .system import LinearSystem
from .transitions import Edge, TransitionSystem
from .workspace.decomposition import CellDecomposition

__all__ = ["Verdict", "highs_solve_batch", "build_abstraction", "ZERO_MARGIN_TOL"]

log = logging.getLogger("tubejax")

#: Edges with ``|t*|`` at or below this are flagged as zero-margin (valid, but only an exact solver confirms them).
ZERO_MARGIN_TOL = 1e-9


BatchSolver = Callable[..., list]


def build_abstraction(decomp: CellDecomposition, system: LinearSystem, *, zshape: str = "box",
                      z_scale: float = 1.0, L_max: int = 10, eps_min: float = 0.0,
                      pruning: bool = True, solve_batch: BatchSolver = highs_solve_batch,
                      progress: bool = True, on_round: Callable | None = None,
                      method: str = "tube") -> TransitionSystem:
    """Run Algorithm 2.

    Parameters
    ----------
    decomp : CellDecomposition
    system : LinearSystem
    zshape : str
        Cross-section kind (:func:`tubejax.lp.formulations.zshape.make_z`).
    L_max : int
        Largest horizon tried, ``>= 1``.
    pruning : bool
        Apply the sound necessary conditions of :mod:`tubejax.pruning`.
    solve_batch : callable
        ``solve_batch(problems, progress=bar) -> list[Verdict]``. A solver with
        ``supports_deferred = True`` is called with ``defer=True`` and may return a
        :class:`~tubejax.lp.evidence.verdict.Pending` for a likely edge: the pair leaves the
        later rounds at once, its HiGHS confirmation runs on while they are solved,
        and the edge enters the result only once confirmed (if HiGHS disagrees,
        the pair's later horizons are solved after all, so the result is Algorithm 2's).
    method : str
        Recorded in the result (``'tube'``, ``'openloop'``, ``'exact2d'``); it must
        match ``solve_batch`` (the evidence each one stores differs).
    on_round : callable, optional
        Called as ``on_round(L, new_edges, new_tubes)`` after each round with the
        edges confirmed since the last call (an edge carries its own ``L``), so
        callers can write finished work incrementally.

    Returns
    -------
    TransitionSystem
    """
    if not isinstance(L_max, (int, np.integer)) or L_max < 1:
        raise ValueError(f"L_max must be an integer >= 1, got {L_max!r}")
    if decomp.dim != system.n:
        raise ValueError(f"the workspace is {decomp.dim}-D but the system state is {system.n}-D")
    t0 = time.perf_counter()
    N = decomp.n_cells
    Z = tuple(make_z(zshape, c, z_scale) for c in decomp.cells)
    obst = decomp.obstacle_case_matrix()
    if pruning:
        keep, pruned = prune_mask(decomp, system, L_max)
    else:
        keep = np.ones((N, N, L_max), dtype=bool)
        keep[np.arange(N), np.arange(N), :] = False
        pruned = {r: 0 for r in PRUNE_REASONS}
    found = np.zeros((N, N), dtype=bool)       # an edge (or a likely edge being confirmed)
    edges, tubes = [], []
    verdicts = Counter()
    provenance = Counter()
    n_lps = 0
    total = int(keep.sum())
    bar = tqdm(total=total, desc="tube LPs", unit="LP", disable=not progress, leave=False)
    defer = {"defer": True} if getattr(solve_batch, "supports_deferred", False) else {}
    pending: list = []                           # (i, j, L, Pending): likely edges being confirmed
    reopen: list = []                            # (i, j, L): a likely edge HiGHS did not confirm
    held = np.zeros((N, N), dtype=bool)          # refused after later rounds skipped it: the pair
                                                 # waits for the reopen loop (horizons in order)
    new_e, new_t = [], []

    def record(i, j, L, v):
        verdicts[v.status] += 1
        provenance[v.provenance] += 1
        if v.status == "edge":
            found[i, j] = True
            new_e.append(Edge(int(i), int(j), L, float(v.margin), v.provenance))
            new_t.append(v.tube)

    def harvest(block: bool, L_done: int):
        """Settle the confirmations that are done (all of them when ``block``); rounds up to
        ``L_done`` have run."""
        still = []
        for i, j, L, pv in pending:
            if not (block or pv.done()):
                still.append((i, j, L, pv))
                continue
            v = pv.result()
            record(i, j, L, v)
            if v.status != "edge":               # solve its later horizons after all
                # a PDHG tube that HiGHS refuses was never seen; a near-zero margin may be < 0
                level = logging.INFO if v.provenance == "highs-fallback" else logging.WARNING
                log.log(level, "pair (%d, %d) at L=%d: likely edge but HiGHS says %s; "
                        "its later horizons are solved too", i, j, L, v.status)
                found[i, j] = False
                if L_done > L:
                    # rounds L+1 .. L_done skipped the pair: its horizons from L + 1 on are
                    # solved in order after the rounds (not from the next round on, which
                    # would skip horizons and could give a larger L than Algorithm 2's)
                    held[i, j] = True
                    reopen.append((i, j, L))
        pending[:] = still

    def run_round(L, cand, **kw):
        nonlocal n_lps
        probs = [pair_problem(decomp, system, Z[i], int(i), int(j), L, eps_min) for i, j in cand]
        res = solve_batch(probs, progress=bar, **kw)
        n_lps += len(probs)
        for (i, j), v in zip(cand, res):
            if isinstance(v, Pending):
                found[i, j] = True               # leaves the later rounds unless HiGHS disagrees
                pending.append((i, j, L, v))
            else:
                record(i, j, L, v)
        # pairs found now skip later rounds: drop them from the progress total
        fresh = np.zeros_like(found)
        fresh[tuple(np.transpose(cand))] = found[tuple(np.transpose(cand))]
        skipped = int(keep[fresh][:, L:].sum()) if L < L_max else 0
        bar.total = max(bar.n, bar.total - skipped) if skipped else bar.total

    def flush(L):
        nonlocal new_e, new_t
        edges.extend(new_e)
        tubes.extend(new_t)
        if on_round is not None:
            on_round(L, new_e, new_t)
        new_e, new_t = [], []

    for L in range(1, L_max + 1):
        cand = np.argwhere(keep[:, :, L - 1] & ~found & ~held)
        if cand.size:
            tr = time.perf_counter()
            run_round(L, cand, **defer)
            log.info("L=%d: %d LPs, %d edges so far, %.0f LP/s", L, len(cand),
                     len(edges) + len(new_e) + len(pending), len(cand) / max(time.perf_counter() - tr, 1e-9))
        harvest(block=False, L_done=L)
        flush(L)
    tw = time.perf_counter()
    harvest(block=True, L_done=L_max)
    confirm_wait = time.perf_counter() - tw
    flush(L_max)
    while reopen:                                # later horizons of unconfirmed likely edges
        start = {(int(i), int(j)): L0 + 1 for i, j, L0 in reopen}
        reopen.clear()
        for L in range(min(start.values()), L_max + 1):
            cand = np.array([(i, j) for (i, j), L0 in start.items()
                             if L0 <= L and keep[i, j, L - 1] and not found[i, j]], dtype=int)
            if cand.size:
                run_round(L, cand.reshape(-1, 2))
            flush(L)
    bar.close()
    order = sorted(range(len(edges)), key=lambda k: (edges[k].src, edges[k].dst))
    edges = [edges[k] for k in order]
    tubes = [tubes[k] for k in order]
    n_pairs = N * (N - 1)
    n_obst = int(obst.sum())
    stats = {
        "n_cells": N, "n_edges": len(edges), "n_lps": n_lps,
        "seconds": time.perf_counter() - t0,
        "n_pairs": n_pairs, "n_free_pairs": n_pairs - n_obst, "n_obstacle_pairs": n_obst,
        "pruning": bool(pruning), "pruned": pruned, "n_pruned": int(sum(pruned.values())),
        "verdicts": dict(verdicts), "provenance": dict(provenance),
        "n_zero_margin": int(sum(abs(e.margin) <= ZERO_MARGIN_TOL for e in edges)),
        "n_unconfirmed": int(verdicts.get("unconfirmed", 0)),
        "L_max": int(L_max), "zshape": zshape, "confirm_wait_seconds": confirm_wait,
    }
    stats["method"] = method
    return TransitionSystem(decomp, system, Z, edges, tubes, float(eps_min), method, stats)
