"""What a run's files claim beyond each edge's evidence, re-checked or refused (part of
:mod:`tubejax.verify.verifier`'s cheap checks): :func:`compatible` (the edges index the rebuilt
cells), :func:`check_shard` (a shard holds only edges from the sources it owns) and
:func:`check_metrics` (``metrics.json``'s edges, counts and settings recomputed and compared; its
run statistics are measurements, not claims). ``verify`` never relies on ``metrics.json``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..abstraction.candidates import build_candidates
from ..abstraction.shards import shard_owner
from ..transitions.file_format import TransitionFile

__all__ = ["METRICS_FILE", "MEAN_MARGIN_TOL", "compatible", "check_shard", "check_metrics"]

#: The run's flat metrics row, beside ``transitions.json``.
METRICS_FILE = "metrics.json"
#: Largest difference between metrics.json's ``mean_margin`` and the file's: each margin is checked
#: against its evidence to ``MARGIN_TOL`` (:data:`tubejax.verify.verifier.MARGIN_TOL`), so their mean may
#: move as much and still describe the same edges.
MEAN_MARGIN_TOL = 1e-7


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


def _same(claimed, actual, tol: float = 0.0) -> bool:
    if isinstance(claimed, bool) or isinstance(actual, bool):
        return claimed is actual
    if isinstance(actual, float) and claimed is None:          # metrics.json writes NaN as null
        return math.isnan(actual)
    if isinstance(actual, float) and isinstance(claimed, (int, float)):
        return (math.isnan(actual) and math.isnan(claimed)) or abs(float(claimed) - actual) <= tol
    return claimed == actual


def _edge_set(edges):
    """The edges ``[from, to, L]`` as a sorted list of tuples (``None`` when they are not such triples)."""
    out = []
    for e in edges:
        if not (isinstance(e, list) and len(e) == 3 and all(isinstance(v, int) and not isinstance(v, bool) for v in e)):
            return None
        out.append(tuple(e))
    return sorted(out)


def _record_values(rb) -> dict:
    """The metrics row's settings as the inputs record gives them (``{}`` without a record)."""
    if rb.inputs is None:
        return {}
    inp = rb.inputs
    d = inp.disturbance
    return {"method": rb.method, "system": inp.system.name, "disturbance": d.kind,
            "radius": float(getattr(d, "radius", getattr(d, "half_width", float("nan")))),
            "zshape": inp.zshape.kind, "L_max": rb.L_max, "pruning": bool(inp.abstraction.pruning)}


def check_metrics(directory, doc: TransitionFile, rb) -> tuple[list[str], str]:
    """Findings for what ``directory/metrics.json`` claims that the transitions file or its inputs
    record contradict, and a note saying what was compared (or that there is no such file).

    Returns
    -------
    findings : list of str
    note : str
    """
    path = Path(directory) / METRICS_FILE
    if not path.exists():
        return [], f"{METRICS_FILE}: none beside the files (nothing relies on it; nothing to compare)"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        return [f"{path}: cannot read it ({str(exc).splitlines()[0]}); the file is damaged: delete it or rerun"], ""
    if not isinstance(data, dict):
        return [f"{path}: expected a JSON object (one row of run metrics), got {type(data).__name__}"], ""
    edges = [[e.src, e.dst, e.L] for e in doc.edges]
    actual = {"n_cells": len(doc.cells), "n_edges": len(edges), "edges": edges,
              "mean_L": _mean([e.L for e in doc.edges]), "mean_margin": _mean([e.margin for e in doc.edges])}
    tol = {"mean_L": 1e-12 * max(1.0, rb.L_max), "mean_margin": MEAN_MARGIN_TOL}
    source = {k: "the transitions file" for k in actual}
    for k, v in _record_values(rb).items():
        actual[k], source[k] = v, "the inputs record"
    out = []
    for k, v in actual.items():
        if k not in data:
            continue
        if k == "edges":
            claimed = data[k] if isinstance(data[k], list) else None
            if claimed is None or _edge_set(claimed) != sorted(map(tuple, edges)):
                out.append(f"{path}: field 'edges' differs from the {len(edges)} edges [from, to, L] of the "
                           "transitions file (compared as a set)")
        elif not _same(data[k], v, tol.get(k, 0.0)):
            out.append(f"{path}: field {k!r} is {data[k]!r}, {source[k]} gives {v!r}")
    return out, "" if out else (f"{METRICS_FILE}: its edges, counts and settings agree (its run statistics are "
                                "measurements, not compared)")
