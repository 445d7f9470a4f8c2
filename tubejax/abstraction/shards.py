"""Sharding a run of Algorithm 2 over its SOURCE cells (docs/howto/shards.md).

Algorithm 2 treats every pair independently, so shard ``k`` of ``K`` solves the candidate pairs whose
source it owns (:func:`shard_owner`: contiguous ranges of source ids with about equal candidate
instances, deterministic); :func:`tubejax.verify.shard_merge.merge_shards` joins the ``K`` outputs.
"""

from __future__ import annotations

import copy

import numpy as np

from .candidates import Candidates


__all__ = ["shard_owner", "weighted_owner", "source_range", "select_shard", "comparable_record", "RUN_ONLY_SETTINGS"]

#: Settings that change how a run is executed but never its result: ignored when records are compared.
RUN_ONLY_SETTINGS = ("memory_budget_mb",)


def shard_owner(src: np.ndarray, keep: np.ndarray, n_cells: int, count: int) -> np.ndarray:
    """The shard of each source cell, shape ``(n_cells,)``, values in ``[0, count)``.

    Parameters
    ----------
    src : ndarray of int, shape (K,)        source cell of each candidate pair
    keep : ndarray of bool, shape (K, L_max) candidate horizons of each pair
    """
    w = np.bincount(np.asarray(src, dtype=np.int64), weights=np.asarray(keep).sum(axis=1), minlength=n_cells)
    return weighted_owner(w, count)


def weighted_owner(weights: np.ndarray, count: int) -> np.ndarray:
    """The shard of each cell, shape ``(N,)``, values in ``[0, count)`` and nondecreasing: cells in id order
    cut into ``count`` contiguous ranges of about equal total weight (a cell counted at its midpoint).

    Parameters
    ----------
    weights : ndarray of float, shape (N,)   the work of each source cell (candidate instances or pairs)
    count : int
    """
    if count < 1:
        raise ValueError(f"shard count must be >= 1, got {count}")
    w = np.asarray(weights, dtype=float)
    n_cells = len(w)
    total = w.sum()
    if total <= 0:
        return (np.arange(n_cells) * count // max(n_cells, 1)).astype(np.int64)
    mid = np.cumsum(w) - w / 2
    return np.clip(np.floor(mid * count / total), 0, count - 1).astype(np.int64)


def source_range(weights: np.ndarray, count: int, index: int) -> tuple[int, int]:
    """The source cells ``[start, stop)`` of shard ``index`` of ``count`` (:func:`weighted_owner`)."""
    if not 0 <= index < count:
        raise ValueError(f"shard index must be in [0, {count - 1}], got {index}")
    owner = weighted_owner(weights, count)
    return int(np.searchsorted(owner, index, side="left")), int(np.searchsorted(owner, index, side="right"))


def select_shard(cand, n_cells: int, count: int, index: int):
    """The :class:`~tubejax.abstraction.candidates.Candidates` of shard ``index`` of ``count`` (all of them when
    ``count == 1``).

    ``stats['shard']`` records the shard, its source cells and instances; the pruning counts
    stay those of the whole run.
    """

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
