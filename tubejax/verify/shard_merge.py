"""Merging the outputs of the shards of one run (:mod:`tubejax.abstraction.shards`) into the unsharded system.

:func:`merge_shards` loads each shard checked against its recorded sources, checks that the ``K``
outputs come from the same inputs, that each holds only its own sources' edges (and non-edges),
and joins them into the system an unsharded run computes.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np

from ..abstraction.candidates import build_candidates
from ..errors import InputError
from ..transitions.records import NonEdges
from ..abstraction.runstore import record_differences
from ..abstraction.shards import comparable_record, shard_owner
from ..transitions.transition_system import TransitionSystem
from .verifier import load_with_sources
from ..model.zassignment import ZAssignment

__all__ = ["MergeError", "merge_shards", "shard_set"]


class MergeError(InputError):
    """Shard outputs that cannot be merged: missing, duplicated, or of different inputs."""


def _shard_of(record, where) -> tuple[int, int]:
    s = (record or {}).get("abstraction", {}).get("shard") if isinstance(record, dict) else None
    if not isinstance(s, dict) or not isinstance(s.get("count"), int) or not isinstance(s.get("index"), int):
        raise MergeError(f"{where}: its inputs record names no shard (abstraction.shard.count / index): "
                         "not the output of a sharded run")
    return s["count"], s["index"]


def shard_set(records: list, file: str, kind: str = "") -> tuple[dict, int]:
    """``({shard index: directory}, shard count)`` of the shards whose inputs records are ``records``,
    ``[(directory, record)]`` (read from ``directory / file``); refuses a record that names no shard, a
    shard given twice or missing, and shards of different inputs (naming the field; ``kind``: ``'product '``
    for product shards)."""
    d0, ref = records[0]
    seen: dict = {}
    for d, rec in records:
        index = _shard_of(rec, d / file)[1]
        if index in seen:
            raise MergeError(f"shard {index} appears twice: {seen[index]} and {d}")
        diff = record_differences(comparable_record(ref), comparable_record(rec))
        if diff:
            what = "; ".join(f"inputs.{p}: {a!r} in {d0}, {b!r} in {d}" for p, a, b in diff[:5])
            raise MergeError(f"{kind}shards of different inputs: {what}" + (f" (and {len(diff) - 5} more)"
                                                                             if len(diff) > 5 else ""))
        seen[index] = d
    count = _shard_of(ref, d0 / file)[0]
    missing = sorted(set(range(count)) - set(seen))
    if missing:
        raise MergeError(f"missing shard{'s' if len(missing) > 1 else ''} {', '.join(map(str, missing))} of "
                         f"{count} (found {', '.join(str(i) for i in sorted(seen))})")
    return seen, count


def merge_shards(directories, progress: bool = False):
    """Join the transition systems of the shards of one run.

    Parameters
    ----------
    directories : sequence of path
        Each holds one shard's ``transitions.json`` / ``.npz`` (read strictly and checked against
        their recorded sources by :func:`~tubejax.verify.verifier.load_with_sources`).

    Returns
    -------
    TransitionSystem
        Edges of every shard sorted by ``(src, dst)``; its inputs record is the shards' with
        ``shard = {count: 1, index: 0}`` (the unsharded run's); ``stats`` sums the counts and keeps
        each shard's own under ``'shards'``. A ``MergeError`` for no shard, a shard missing or given
        twice, shards of different inputs, or an edge whose source another shard owns.
    """
    shards, count0, ts0 = _read_shards(directories)
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
    pair_z = {}                                  # learned_pair: each shard stored the Z of its own edges
    for index in range(count0):
        Zs = shards[index][1].Z
        if isinstance(Zs, ZAssignment):
            pair_z.update(Zs.pairs)
    Z = ZAssignment(ts0.Z, pair_z) if pair_z else ts0.Z
    return TransitionSystem(ts0.decomposition, ts0.system, Z, edges, [tubes[k] for k in order],
                            ts0.eps_min, ts0.method, stats, record, ts0.min_margin,
                            _merged_nonedges([shards[i] for i in range(count0)], owner), ts0.margin_scaling,
                            ts0.certificate_rows)


def _read_shards(directories) -> tuple[dict, int, TransitionSystem]:
    """Each shard's ``(directory, TransitionSystem)`` by its index, the shard count and the first system;
    refuses what :func:`shard_set` refuses, and shards of different certificate rows or margin scaling."""
    dirs = [Path(d) for d in directories]
    if not dirs:
        raise MergeError("no shard outputs to merge")
    systems = [(d, load_with_sources(d)) for d in dirs]
    seen, count0 = shard_set([(d, ts.inputs) for d, ts in systems], "transitions.json")
    d0, ts0 = systems[0]
    for d, ts in systems[1:]:
        if ts.certificate_rows != ts0.certificate_rows:
            raise MergeError(f"shards whose certificates index other rows: {ts0.certificate_rows} in {d0}, "
                             f"{ts.certificate_rows} in {d} (rerun the older shard with this tubejax)")
        if ts.margin_scaling != ts0.margin_scaling:
            raise MergeError(f"shards whose margins are scaled differently: {ts0.margin_scaling!r} in {d0}, "
                             f"{ts.margin_scaling!r} in {d} (rerun the older shard with this tubejax)")
    by_dir = dict(systems)
    return {index: (d, by_dir[d]) for index, d in seen.items()}, count0, ts0


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
    for key in ("n_lps", "n_zero_margin", "n_unconfirmed", "seconds", "problem_seconds", "solve_seconds",
                "n_translated", "exact_decision_seconds"):
        out[key] = sum(s.get(key, 0) for s in stats)
    for key in ("verdicts", "provenance", "nonedge_evidence", "n_decided_exactly"):
        total: dict = {}
        for s in stats:
            for k, v in (s.get(key) or {}).items():
                total[k] = total.get(k, 0) + v
        out[key] = total
    out["n_edges"] = n_edges
    out["shards"] = [{k: s.get(k) for k in ("shard", "n_edges", "n_lps", "seconds")} for s in stats]
    return out
