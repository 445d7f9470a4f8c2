"""Merging the shards of one product run (docs/howto/shards.md#product-runs) into the unsharded product system.

Shard ``k`` of ``K`` solved every factor table and joined the source cells ``[start_k, stop_k)``.
:func:`merge_product_shards` loads each shard (the problem rebuilt once and checked against every
other's), refuses shards of different inputs, a missing or duplicated shard, differing factor tables
and an edge whose source another shard owns, then joins the edges into the system an unsharded run
computes (factor margins recomputed, joint edges with their joint verdicts).
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np

from ..abstraction.product_abstraction import JOINT, ProductSystem
from ..abstraction.product_store import ProductProblem, load_product
from ..transitions.product_file import PRODUCT_STEM
from .shard_merge import MergeError, shard_set

__all__ = ["merge_product_shards"]

#: Counts of the factor phase: the same in every shard, kept once.
FACTOR_STATS = ("groups", "n_factor_cells", "n_factor_lps", "n_factor_pruned", "n_factor_edges", "seconds_detect",
                "seconds_factors", "solver", "variants")
#: Counts of the join and the joint LPs: summed over the shards.
SUMMED_STATS = ("n_box_tested", "n_joint_pairs", "n_joint_lps", "n_joint_reused", "n_joint_translated", "seconds_join",
                "seconds_joint", "seconds")


def _record(d: Path, stem: str) -> dict:
    """The inputs record of ``d/<stem>.json`` (the file itself is read strictly by ``load_product`` later)."""
    path = d / f"{stem}.json"
    try:
        return json.loads(path.read_text()).get("inputs")
    except (OSError, ValueError, AttributeError) as exc:
        raise MergeError(f"{path}: cannot read its inputs record: {exc}") from None


def _read(directories, stem: str) -> tuple[list, int, dict]:
    """``[(directory, index, ProductSystem)]`` by shard index, the shard count and the first record; refuses
    no shard, one given twice or missing, and shards of different inputs (naming the field)."""
    dirs = [Path(d) for d in directories]
    if not dirs:
        raise MergeError("no product shard outputs to merge")
    records = [(d, _record(d, stem)) for d in dirs]
    ref = records[0][1]
    seen, count = shard_set(records, f"{stem}.json", "product ")
    first = load_product(seen[0], stem=stem)
    problem = ProductProblem(first.decomposition, first.system, first.Z)
    shards = [(seen[0], 0, first)] + [(seen[k], k, load_product(seen[k], problem, stem)) for k in range(1, count)]
    return shards, count, ref


def _check_tables(shards: list) -> None:
    """Refuse shards whose factor tables (the feasible factor LPs) differ from the first shard's."""
    d0, _, ps0 = shards[0]
    for d, index, ps in shards[1:]:
        for g, (t0, t) in enumerate(zip(ps0.tables, ps.tables)):
            bad = np.argwhere(t0.feasible != t.feasible)
            if len(bad):
                v, L1, a, b = bad[0].tolist()
                raise MergeError(f"group {g}'s factor tables differ between shard 0 ({d0}) and shard {index} ({d}): "
                                 f"factor pair {a}->{b} (L={L1 + 1}, variant {v}) is feasible in "
                                 f"{'shard 0' if t0.feasible[v, L1, a, b] else f'shard {index}'} only "
                                 "(rerun the shards with a deterministic solver, e.g. solver=highs)")


def _check_ownership(shards: list, count: int) -> None:
    """Refuse shards whose recorded source ranges (``stats['shard']``: ``start``, ``stop``) do not cut the
    cells into consecutive ranges in shard order, and an edge or joint verdict whose source cell lies
    outside its shard's range."""
    expect = 0
    for d, index, ps in shards:
        rec = ps.stats.get("shard") if isinstance(ps.stats, dict) else None
        try:
            start, stop = int(rec["start"]), int(rec["stop"])
        except (TypeError, KeyError, ValueError):
            raise MergeError(f"{d / (PRODUCT_STEM + '.json')}: stats.shard records no source range "
                             f"(start, stop) of shard {index}") from None
        last = index == count - 1
        if start != expect or stop < start or (last and stop != ps.n_cells):
            raise MergeError(f"{d / (PRODUCT_STEM + '.json')}: shard {index}'s source cells [{start}, {stop}) do not "
                             f"continue the shards before it (expected a range starting at {expect}"
                             + (f" and ending at {ps.n_cells}, the number of cells)" if last else ")"))
        expect = stop
        src = np.concatenate([ps.src, np.array([k[0] for k in ps.joint], dtype=np.int64)])
        dst = np.concatenate([ps.dst, np.array([k[1] for k in ps.joint], dtype=np.int64)])
        bad = np.flatnonzero((src < start) | (src >= stop))
        if len(bad):
            k = int(bad[0])
            raise MergeError(f"{d / (PRODUCT_STEM + '.npz')}: edge {src[k]}->{dst[k]} has a source cell "
                             f"outside shard {index}'s source cells [{start}, {stop})")


def _factor_margins(ps0: ProductSystem, src, dst, L, variant) -> np.ndarray:
    """The least factor margin of each factor edge in ``ps0``'s tables (joint edges: ``nan``)."""
    cf = ps0.structure.cell_factor
    out = np.full(len(src), np.nan)
    k = np.flatnonzero(variant != JOINT)
    out[k] = np.inf
    for g, t in enumerate(ps0.tables):
        out[k] = np.minimum(out[k], t.margin[variant[k], L[k] - 1, cf[src[k], g], cf[dst[k], g]])
    return out


def merge_product_shards(directories, stem: str = PRODUCT_STEM) -> tuple[ProductSystem, dict]:
    """Join the product shards of one run (see the module docstring).

    Parameters
    ----------
    directories : sequence of path
        Each holds one shard's ``<stem>.json|npz``.
    stem : str

    Returns
    -------
    (ProductSystem, dict)
        The merged system (edges sorted by ``(src, dst)``; ``stats`` sums the join's and joint LPs' counts,
        keeps the factor phase's once and each shard's own under ``'shards'``) and its inputs record:
        the shards' with ``abstraction.shard = {count: 1, index: 0}`` (the unsharded run's).

    Raises
    ------
    MergeError
        No shard, a shard missing or given twice, shards of different inputs or factor tables, an edge
        whose source another shard owns.
    ProductFileError
        A shard's files are damaged or differ from their sources.
    """
    shards, count, ref = _read(directories, stem)
    _check_tables(shards)
    _check_ownership(shards, count)
    ps0 = shards[0][2]
    cat = {f: np.concatenate([getattr(ps, f) for _, _, ps in shards]) for f in ("src", "dst", "L", "margin", "variant")}
    order = np.lexsort((cat["dst"], cat["src"]))
    src, dst, L, margin, variant = (cat[f][order] for f in ("src", "dst", "L", "margin", "variant"))
    margin = np.where(variant == JOINT, margin, _factor_margins(ps0, src, dst, L, variant))
    joint = {}
    for _, _, ps in shards:
        joint.update(ps.joint)
    stats = {k: ps0.stats[k] for k in FACTOR_STATS if k in ps0.stats}
    for k in SUMMED_STATS:
        stats[k] = sum(float(ps.stats.get(k, 0)) for _, _, ps in shards)
        stats[k] = int(stats[k]) if k.startswith("n_") else stats[k]
    stats["n_edges"] = int(len(src))
    stats["shards"] = [ps.stats.get("shard") for _, _, ps in shards]
    record = copy.deepcopy(ref)
    record["abstraction"]["shard"] = {"count": 1, "index": 0}
    merged = ProductSystem(ps0.decomposition, ps0.system, ps0.Z, ps0.structure, ps0.tables, src, dst, L, margin,
                           variant, joint, ps0.L_max, ps0.eps_min, stats)
    return merged, record
