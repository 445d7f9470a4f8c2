"""Sharding a run of Algorithm 2 over its SOURCE cells, and merging the shards' outputs.

Algorithm 2 treats every pair independently, so a partition of the source cells splits a run
into jobs that share nothing: shard ``k`` of ``K`` solves the candidate pairs ``(i, j)`` whose
source ``i`` it owns (:func:`shard_owner`) and writes a transition system holding just their
edges; :func:`merge_shards` checks that the ``K`` outputs come from the same inputs, that each
holds only its own sources' edges, and joins them into the system an unsharded run computes.

The partition is deterministic: source cells in id order, cut into ``K`` contiguous ranges of
about equal candidate instances (the instances of a cell are counted at its midpoint).
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np

from .errors import InputError
from .refutations import NonEdges
from .runstore import record_differences

__all__ = ["MergeError", "shard_owner", "select_shard", "merge_shards", "comparable_record",
           "RUN_ONLY_SETTINGS"]

#: Settings that change how a run is executed but never its result: ignored when records are compared.
RUN_ONLY_SETTINGS = ("memory_budget_mb",)


class MergeError(InputError):
    """Shard outputs that cannot be merged: missing, duplicated, or of different inputs."""


def shard_owner(src: np.ndarray, keep: np.ndarray, n_cells: int, count: int) -> np.ndarray:
    """The shard of each source cell, shape ``(n_cells,)``, values in ``[0, count)``.

    Parameters
    ----------
    src : ndarray of int, shape (K,)        source cell of each candidate pair
    keep : ndarray of bool, shape (K, L_max) candidate horizons of each pair
    """
    if count < 1:
        raise ValueError(f"shard count must be >= 1, got {count}")
    w = np.bincount(np.asarray(src, dtype=np.int64), weights=np.asarray(keep).sum(axis=1),
                    minlength=n_cells).astype(float)
    total = w.sum()
    if total <= 0:
        return (np.arange(n_cells) * count // max(n_cells, 1)).astype(np.int64)
    mid = np.cumsum(w) - w / 2
    return np.clip(np.floor(mid * count / total), 0, count - 1).astype(np.int64)


def select_shard(cand, n_cells: int, count: int, index: int):
    """The :class:`~tubejax.candidates.Candidates` of shard ``index`` of ``count`` (all of them when ``count == 1``).

    ``stats['shard']`` records the shard, its source cells and instances; the pruning counts
    stay those of the whole run.
    """
    from .candidates import Candidates

    if not 0 <= index < count:
        raise ValueError(f"shard index must be in [0, {count - 1}], got {index}")
    owner = shard_owner(cand.src, cand.keep, n_cells, count)
    mine = owner[cand.src] == index
    stats = dict(cand.stats, shard={"count": int(count), "index": int(index),
                                    "n_sources": int((owner == index).sum()), "n_pairs": int(mine.sum()),
                                    "n_instances": int(cand.keep[mine].sum())})
    return Candidates(cand.src[mine], cand.dst[mine], cand.keep[mine], cand.obstacle[mine], dict(cand.pruned),
                      stats)


def comparable_record(record: dict, drop_shard_index: bool = True) -> dict:
    """An inputs record without what may differ between jobs of one run (see :data:`RUN_ONLY_SETTINGS`)."""
    r = copy.deepcopy(record)
    a = r.get("abstraction", {}) if isinstance(r, dict) else {}
    for key in RUN_ONLY_SETTINGS:
        a.pop(key, None)
    if drop_shard_index and isinstance(a.get("shard"), dict):
        a["shard"].pop("index", None)
    z = r.get("zshape") if isinstance(r, dict) else None
    if isinstance(z, dict) and isinstance(z.get("file"), dict):
        z["file"].pop("resolved", None)          # each job saves its own (identical, by SHA-256) learned_z.json
    return r


def _shard_of(record, where) -> tuple[int, int]:
    s = (record or {}).get("abstraction", {}).get("shard") if isinstance(record, dict) else None
    if not isinstance(s, dict) or not isinstance(s.get("count"), int) or not isinstance(s.get("index"), int):
        raise MergeError(f"{where}: its inputs record names no shard (abstraction.shard.count / index): "
                         "not the output of a sharded run")
    return s["count"], s["index"]


def merge_shards(directories, progress: bool = False):
    """Join the transition systems of the shards of one run.

    Parameters
    ----------
    directories : sequence of path
        Each holds one shard's ``transitions.json`` / ``.npz`` (read strictly and checked against
        their recorded sources by :meth:`~tubejax.transitions.TransitionSystem.load`).

    Returns
    -------
    TransitionSystem
        Edges of every shard sorted by ``(src, dst)``; its inputs record is the shards' with
        ``shard = {count: 1, index: 0}`` (the unsharded run's); ``stats`` sums the counts and keeps
        each shard's own under ``'shards'``.

    Raises
    ------
    MergeError
        No shard, a shard missing or given twice, shards of different inputs, or an edge whose
        source another shard owns.
    """
    from .candidates import build_candidates
    from .transitions import TransitionSystem

    dirs = [Path(d) for d in directories]
    if not dirs:
        raise MergeError("no shard outputs to merge")
    systems, shards = [], {}
    for d in dirs:
        ts = TransitionSystem.load(d)
        count, index = _shard_of(ts.inputs, d / "transitions.json")
        if index in shards:
            raise MergeError(f"shard {index} appears twice: {shards[index][0]} and {d}")
        shards[index] = (d, ts)
        systems.append((count, index, d, ts))
    count0, _, d0, ts0 = systems[0]
    ref = comparable_record(ts0.inputs)
    for count, index, d, ts in systems[1:]:
        diff = record_differences(ref, comparable_record(ts.inputs))
        if diff:
            what = "; ".join(f"{p}: {a!r} in {d0}, {b!r} in {d}" for p, a, b in diff[:5])
            raise MergeError(f"shards of different inputs: {what}" + (f" (and {len(diff) - 5} more)"
                                                                       if len(diff) > 5 else ""))
    missing = sorted(set(range(count0)) - set(shards))
    if missing:
        raise MergeError(f"missing shard{'s' if len(missing) > 1 else ''} {', '.join(map(str, missing))} of "
                         f"{count0} (found {', '.join(str(i) for i in sorted(shards))})")
    a = ts0.inputs["abstraction"]
    cand = build_candidates(ts0.decomposition, ts0.system, int(a["L_max"]), bool(a.get("pruning", True)))
    owner = shard_owner(cand.src, cand.keep, ts0.n_cells, count0)
    edges, tubes = [], []
    for index in range(count0):
        d, ts = shards[index]
        for e, t in zip(ts.edges, ts.tubes):
            if owner[e.src] != index:
                raise MergeError(f"{d / 'transitions.json'}: edge {e.src}->{e.dst} has a source cell of shard "
                                 f"{owner[e.src]}, not of shard {index}")
            edges.append(e)
            tubes.append(t)
    order = sorted(range(len(edges)), key=lambda k: (edges[k].src, edges[k].dst))
    record = copy.deepcopy(ts0.inputs)
    record["abstraction"]["shard"] = {"count": 1, "index": 0}
    edges = [edges[k] for k in order]
    stats = _merged_stats([shards[i][1].stats for i in range(count0)], len(edges))
    stats["proof"] = {lvl: sum(e.proof == lvl for e in edges) for lvl in ("exact", "float")}
    stats["proof"]["unknown"] = sum(e.proof is None for e in edges)
    from .zassignment import ZAssignment
    pair_z = {}                                  # learned_pair: each shard stored the Z of its own edges
    for index in range(count0):
        Zs = shards[index][1].Z
        if isinstance(Zs, ZAssignment):
            pair_z.update(Zs.pairs)
    Z = ZAssignment(ts0.Z, pair_z) if pair_z else ts0.Z
    return TransitionSystem(ts0.decomposition, ts0.system, Z, edges, [tubes[k] for k in order],
                            ts0.eps_min, ts0.method, stats, record, ts0.min_margin,
                            _merged_nonedges([shards[i] for i in range(count0)], owner))


def _merged_nonedges(shards: list, owner: np.ndarray):
    """The shards' non-edge records together (``None`` unless every shard has them), each checked
    to belong to its shard's source cells."""
    if any(ts.nonedges is None for _, ts in shards):
        return None
    for index, (d, ts) in enumerate(shards):
        bad = np.flatnonzero(owner[ts.nonedges.src] != index) if len(ts.nonedges) else []
        if len(bad):
            k = int(bad[0])
            raise MergeError(f"{d / 'transitions.npz'}: non-edge {ts.nonedges.src[k]}->{ts.nonedges.dst[k]} has a "
                             f"source cell of shard {owner[ts.nonedges.src[k]]}, not of shard {index}")
    parts = [ts.nonedges for _, ts in shards]
    return NonEdges(*(np.concatenate([getattr(p, f) for p in parts]).astype(np.int64) for f in ("src", "dst", "L")),
                    [r for p in parts for r in p.refutations]).sorted()


def _merged_stats(stats: list, n_edges: int) -> dict:
    """Counts summed over the shards; the candidate counts (the same in every shard) kept once."""
    out = {k: v for k, v in stats[0].items() if k not in ("shard", "rounds", "config", "solver_stats")}
    for key in ("n_lps", "n_zero_margin", "n_unconfirmed", "seconds", "problem_seconds", "solve_seconds"):
        out[key] = sum(s.get(key, 0) for s in stats)
    for key in ("verdicts", "provenance"):
        total: dict = {}
        for s in stats:
            for k, v in (s.get(key) or {}).items():
                total[k] = total.get(k, 0) + v
        out[key] = total
    out["n_edges"] = n_edges
    out["shards"] = [{k: s.get(k) for k in ("shard", "n_edges", "n_lps", "seconds")} for s in stats]
    return out
