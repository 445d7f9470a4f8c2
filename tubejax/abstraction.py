"""Algorithm 2: every ordered pair x horizon -> a verified transition system.

The pairs and horizons come from :func:`tubejax.candidates.build_candidates` as sparse
arrays (a k-d tree over reach boxes, then the sound pruning rules; no all-pairs step).
Horizons run in rounds ``L = 1, 2, ..., L_max``; in each round every candidate pair
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
from .candidates import build_candidates
from .problem import pair_problems
from .system import LinearSystem
from .transitions import Edge, TransitionSystem
from .workspace.decomposition import CellDecomposition

__all__ = ["Verdict", "highs_solve_batch", "build_abstraction", "cross_sections", "ZERO_MARGIN_TOL"]

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
        Its ``stats`` hold, besides the counts of edges, LPs and verdicts: ``n_pairs``
        (``N (N-1)``), ``n_candidate_pairs`` (from the spatial index), ``n_tested_pairs`` and
        ``n_obstacle_case_candidates`` / ``n_free_case_candidates`` (pairs whose obstacle case
        was computed), ``pruned`` (instances per reason of :data:`tubejax.pruning.PRUNE_REASONS`),
        ``seconds_before_first_lp``, ``problem_seconds`` and ``solve_seconds`` (and per round in
        ``rounds``), the ``seconds_*`` of the candidate steps, and ``pdhg_lps_per_second`` /
        ``highs_lps_per_second`` when the solver's counters (or a solver without them, all
        HiGHS) tell them.
    """
    if not isinstance(L_max, (int, np.integer)) or L_max < 1:
        raise ValueError(f"L_max must be an integer >= 1, got {L_max!r}")
    if decomp.dim != system.n:
        raise ValueError(f"the workspace is {decomp.dim}-D but the system state is {system.n}-D")
    t0 = time.perf_counter()
    N = decomp.n_cells
    Z = cross_sections(decomp, zshape, z_scale)
    cand = build_candidates(decomp, system, int(L_max), pruning)
    src, dst, keep, obst = cand.src, cand.dst, cand.keep, cand.obstacle
    found = np.zeros(len(src), dtype=bool)      # an edge (or a likely edge being confirmed), per pair
    edges, tubes = [], []
    verdicts = Counter()
    provenance = Counter()
    timing = {"n_lps": 0, "problem_seconds": 0.0, "solve_seconds": 0.0, "first_lp": None}
    rounds: list = []
    solver_stats0 = _numeric(getattr(solve_batch, "stats", None))
    bar = tqdm(total=cand.n_instances, desc="tube LPs", unit="LP", disable=not progress, leave=False)
    defer = {"defer": True} if getattr(solve_batch, "supports_deferred", False) else {}
    pending: list = []                           # (pair index, L, Pending): likely edges being confirmed
    reopen: list = []                            # (pair index, L): a likely edge HiGHS did not confirm
    held = np.zeros(len(src), dtype=bool)       # refused after later rounds skipped it: waits for the
                                                 # reopen loop, which solves its horizons in order
    new_e, new_t = [], []

    def record(k, L, v):
        verdicts[v.status] += 1
        provenance[v.provenance] += 1
        if v.status == "edge":
            found[k] = True
            new_e.append(Edge.from_verdict(int(src[k]), int(dst[k]), L, v))
            new_t.append(v.tube)

    def harvest(block: bool, L_done: int):
        """Settle the confirmations that are done (all of them when ``block``); rounds up to
        ``L_done`` have run."""
        still = []
        for k, L, pv in pending:
            if not (block or pv.done()):
                still.append((k, L, pv))
                continue
            v = pv.result()
            record(k, L, v)
            if v.status != "edge":               # solve its later horizons after all
                # a PDHG tube that HiGHS refuses was never seen; a near-zero margin may be < 0
                level = logging.INFO if v.provenance == "highs-fallback" else logging.WARNING
                log.log(level, "pair (%d, %d) at L=%d: likely edge but HiGHS says %s; "
                        "its later horizons are solved too", src[k], dst[k], L, v.status)
                found[k] = False
                if L_done > L:
                    # rounds L+1 .. L_done skipped the pair: its horizons from L + 1 on are solved
                    # in order after the rounds (not from the next round on, which would skip
                    # horizons and could give a larger L than Algorithm 2's); refused right after
                    # its own round, it simply goes on in the next round
                    held[k] = True
                    reopen.append((k, L))
        pending[:] = still

    def run_round(L, ks, **kw):
        """Solve horizon ``L`` of the pairs ``ks`` (indices into ``src``/``dst``)."""
        tp = time.perf_counter()
        probs = pair_problems(decomp, system, Z, src[ks], dst[ks], L, obst[ks], eps_min)
        ts = time.perf_counter()
        if timing["first_lp"] is None:
            timing["first_lp"] = ts - t0
        res = solve_batch(probs, progress=bar, **kw)
        te = time.perf_counter()
        timing["n_lps"] += len(probs)
        timing["problem_seconds"] += ts - tp
        timing["solve_seconds"] += te - ts
        rounds.append({"L": int(L), "n_lps": len(probs), "problem_seconds": ts - tp,
                       "solve_seconds": te - ts})
        for k, v in zip(ks, res):
            if isinstance(v, Pending):
                found[k] = True                  # leaves the later rounds unless HiGHS disagrees
                pending.append((k, L, v))
            else:
                record(k, L, v)
        # pairs found now skip later rounds: drop them from the progress total
        skipped = int(keep[ks[found[ks]], L:].sum()) if L < L_max else 0
        bar.total = max(bar.n, bar.total - skipped) if skipped else bar.total

    def flush(L):
        nonlocal new_e, new_t
        edges.extend(new_e)
        tubes.extend(new_t)
        if on_round is not None:
            on_round(L, new_e, new_t)
        new_e, new_t = [], []

    for L in range(1, L_max + 1):
        ks = np.flatnonzero(keep[:, L - 1] & ~found & ~held)
        if ks.size:
            tr = time.perf_counter()
            run_round(L, ks, **defer)
            log.info("L=%d: %d LPs, %d edges so far, %.0f LP/s", L, len(ks),
                     len(edges) + len(new_e) + len(pending), len(ks) / max(time.perf_counter() - tr, 1e-9))
        harvest(block=False, L_done=L)
        flush(L)
    tw = time.perf_counter()
    harvest(block=True, L_done=L_max)
    confirm_wait = time.perf_counter() - tw
    flush(L_max)
    while reopen:                                # later horizons of unconfirmed likely edges
        start = {int(k): L0 + 1 for k, L0 in reopen}
        reopen.clear()
        for L in range(min(start.values()), L_max + 1):
            ks = np.array(sorted(k for k, L0 in start.items() if L0 <= L and keep[k, L - 1] and not found[k]),
                          dtype=int)
            if ks.size:
                run_round(L, ks)
            flush(L)
    bar.close()
    order = sorted(range(len(edges)), key=lambda k: (edges[k].src, edges[k].dst))
    edges = [edges[k] for k in order]
    tubes = [tubes[k] for k in order]
    pruned = cand.pruned
    seconds = time.perf_counter() - t0
    stats = {
        "n_cells": N, "n_edges": len(edges), "n_lps": timing["n_lps"], "seconds": seconds,
        "n_pairs": N * (N - 1), **cand.stats,
        "pruning": bool(pruning), "pruned": pruned, "n_pruned": int(sum(pruned.values())),
        "verdicts": dict(verdicts), "provenance": dict(provenance),
        "n_zero_margin": int(sum(abs(e.margin) <= ZERO_MARGIN_TOL for e in edges)),
        "n_unconfirmed": int(verdicts.get("unconfirmed", 0)),
        "L_max": int(L_max), "zshape": zshape, "confirm_wait_seconds": confirm_wait,
        "seconds_before_first_lp": seconds if timing["first_lp"] is None else timing["first_lp"],
        "problem_seconds": timing["problem_seconds"], "solve_seconds": timing["solve_seconds"],
        "rounds": rounds,
    }
    stats.update(_lp_rates(solver_stats0, _numeric(getattr(solve_batch, "stats", None)), timing))
    stats["method"] = method
    ts = TransitionSystem(decomp, system, Z, edges, tubes, float(eps_min), method, stats)
    ts.prove()              # proof levels: the verdicts proved the tubes, this the safe sets
    return ts


def cross_sections(decomp: CellDecomposition, zshape: str, z_scale: float) -> tuple:
    """``Z`` of each cell (:func:`~tubejax.lp.formulations.zshape.make_z`), built once per cell shape.

    Two cells share one ``Z`` object when their vertices about the vertex mean are equal bit
    for bit, so the result is the same as calling ``make_z`` per cell.
    """
    out, seen = [], {}
    for c in decomp.cells:
        key = (c.vertices - c.vertices.mean(axis=0)).tobytes() + bytes(str(c.vertices.shape), "ascii")
        if key not in seen:
            seen[key] = make_z(zshape, c, z_scale)
        out.append(seen[key])
    return tuple(out)


def _numeric(stats) -> dict:
    """The numeric entries of a solver's ``stats`` dict (a copy), or ``{}``."""
    if not isinstance(stats, dict):
        return {}
    return {k: v for k, v in stats.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


def _lp_rates(before: dict, after: dict, timing: dict) -> dict:
    """LP/s of the PDHG and HiGHS paths over this run (from the solver's counters when it has them).

    ``pdhg_lps_per_second``: LPs through PDHG over PDHG seconds (compile excluded);
    ``highs_lps_per_second``: HiGHS solves (confirmations + undecided) over the seconds spent
    inside HiGHS. A solver without counters (sequential HiGHS) is all HiGHS.
    """
    d = {k: after[k] - before.get(k, 0) for k in after}
    if "pdhg_seconds" not in d:
        if not after:
            return {"highs_lps_per_second": timing["n_lps"] / max(timing["solve_seconds"], 1e-9)}
        return {}
    n_highs = d.get("sent_to_highs", 0) + d.get("highs_confirmations", 0)
    return {"pdhg_lps_per_second": d.get("n_lps", 0) / max(d["pdhg_seconds"], 1e-9),
            "highs_lps_per_second": n_highs / max(d.get("highs_cpu_seconds", 0.0), 1e-9),
            "n_highs_solves": int(n_highs)}
