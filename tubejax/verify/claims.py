"""What a run's files claim beyond each edge's evidence, re-checked or refused (part of
:mod:`tubejax.verify.verifier`'s cheap checks).

* :func:`compatible` -- whether the edges of a file can be checked against the problem rebuilt
  from its inputs record at all (same number of cells: edge ids index the rebuilt cells);
* :func:`check_shard` -- a file whose inputs record names shard ``k`` of ``K > 1`` holds only
  edges leaving the source cells shard ``k`` owns (:func:`tubejax.abstraction.shards.shard_owner`, over the
  candidates the run had: :func:`tubejax.abstraction.candidates.build_candidates` with its ``L_max`` and
  ``pruning``);
* :func:`check_metrics` -- ``metrics.json`` beside ``transitions.json`` (one flat row per run,
  written by ``experiments/abstract.py`` and ``experiments/radius.py``): its edge list and
  counts are recomputed from the transitions file, its settings compared with the inputs record,
  its run statistics with the file's ``stats``; an unreadable one is refused. Keys it does not
  know are not claims about the transition system and are left alone.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..abstraction.candidates import build_candidates
from ..abstraction.shards import shard_owner
from ..transitions.file_format import TransitionFile

__all__ = ["METRICS_FILE", "compatible", "check_shard", "check_metrics"]

#: The run's flat metrics row, beside ``transitions.json``.
METRICS_FILE = "metrics.json"
#: metrics.json keys that copy a run statistic of ``transitions.json``'s ``stats`` (compared where both exist).
_STATS_KEYS = ("n_lps", "n_pruned", "n_translated", "n_zero_margin", "seconds", "compile_seconds", "learn_seconds")


def compatible(doc: TransitionFile, rb) -> str:
    """``''`` when the edges of ``doc`` can be checked against the rebuilt problem ``rb``, else why not."""
    n = rb.decomposition.n_cells
    if len(doc.cells) != n:
        return (f"not checked: the file's {len(doc.cells)} cells are not the {n} cells of the workspace its "
                "inputs record names")
    return ""


def check_shard(doc: TransitionFile, rb) -> list[str]:
    """Findings for edges of a shard's file whose source cell another shard owns."""
    shard = rb.inputs.abstraction.shard if rb.inputs is not None else None
    if shard is None or shard.count <= 1 or not doc.edges:
        return []
    N = rb.decomposition.n_cells
    cand = build_candidates(rb.decomposition, rb.system, rb.L_max, bool(rb.inputs.abstraction.pruning))
    owner = shard_owner(cand.src, cand.keep, N, shard.count)
    foreign = [k for k, e in enumerate(doc.edges) if owner[e.src] != shard.index]
    if not foreign:
        return []
    k = foreign[0]
    e = doc.edges[k]
    mine = np.flatnonzero(owner == shard.index)
    own = f"cells {mine[0]}..{mine[-1]}" if mine.size else "no cell"
    return [f"inputs.abstraction.shard: the file claims shard {shard.index} of {shard.count}, which owns the "
            f"source {own}, but {len(foreign)} of its {len(doc.edges)} edges leave cells another shard owns "
            f"(e.g. edges[{k}] {e.src}->{e.dst}, whose source belongs to shard {owner[e.src]})"]


def _mean(values) -> float:
    return float(sum(values) / len(values)) if values else float("nan")


def _same(claimed, actual) -> bool:
    if isinstance(claimed, bool) or isinstance(actual, bool):
        return claimed is actual
    if isinstance(actual, float) and claimed is None:          # metrics.json writes NaN as null
        return math.isnan(actual)
    if isinstance(actual, float) and isinstance(claimed, (int, float)):
        return (math.isnan(actual) and math.isnan(claimed)) or float(claimed) == actual
    return claimed == actual


def _record_values(rb) -> dict:
    """The metrics row's settings as the inputs record gives them (``{}`` without a record)."""
    if rb.inputs is None:
        return {}
    inp = rb.inputs
    d = inp.disturbance
    return {"method": rb.method, "solver": rb.solver, "system": inp.system.name, "disturbance": d.kind,
            "radius": float(getattr(d, "radius", getattr(d, "half_width", float("nan")))),
            "zshape": inp.zshape.kind, "L_max": rb.L_max, "pruning": bool(inp.abstraction.pruning)}


def check_metrics(directory, doc: TransitionFile, rb) -> list[str]:
    """Findings for what ``directory/metrics.json`` claims that the transitions file or its inputs
    record contradict (none when there is no such file)."""
    path = Path(directory) / METRICS_FILE
    if not path.exists():
        return []
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        return [f"{path}: cannot read it ({str(exc).splitlines()[0]}); the file is damaged: delete it or rerun"]
    if not isinstance(data, dict):
        return [f"{path}: expected a JSON object (one row of run metrics), got {type(data).__name__}"]
    edges = [[e.src, e.dst, e.L] for e in doc.edges]
    actual = {"n_cells": len(doc.cells), "n_edges": len(edges), "edges": edges,
              "mean_L": _mean([e.L for e in doc.edges]), "mean_margin": _mean([e.margin for e in doc.edges])}
    source = {k: "the transitions file" for k in actual}
    for k, v in _record_values(rb).items():
        actual[k], source[k] = v, "the inputs record"
    for k in _STATS_KEYS:
        if k in doc.stats:
            actual[k], source[k] = doc.stats[k], "the transitions file's stats"
    out = []
    for k, v in actual.items():
        if k in data and not _same(data[k], v):
            if k == "edges":
                out.append(f"{path}: field 'edges' differs from the {len(edges)} edges [from, to, L] of the "
                           "transitions file")
            else:
                out.append(f"{path}: field {k!r} is {data[k]!r}, {source[k]} gives {v!r}")
    return out
