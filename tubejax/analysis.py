"""Collect sweep results into one table and measure conservatism.

Each Hydra job of ``experiments/abstract.py`` writes ``metrics.json`` (one flat
row); :func:`collect_metrics` gathers every one under a multirun directory.
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

__all__ = ["collect_metrics", "add_conservatism", "edge_sets", "GROUP_KEYS"]

#: Columns that identify one abstraction problem apart from the method and Z shape.
GROUP_KEYS = ["workspace", "system", "disturbance", "radius", "L_max"]


def collect_metrics(root) -> pd.DataFrame:
    """One row per ``metrics.json`` under ``root`` (searched recursively).

    Returns
    -------
    pandas.DataFrame
        The metrics columns plus ``job_dir``; the bulky ``edges`` list is dropped
        (see :func:`edge_sets`). Rows are sorted by method, zshape, radius, L_max.
    """
    rows = []
    for path in sorted(Path(root).rglob("metrics.json")):
        row = json.loads(path.read_text())
        row.pop("edges", None)
        row["job_dir"] = str(path.parent)
        rows.append(row)
    if not rows:
        raise FileNotFoundError(f"{root}: no metrics.json found (run a sweep with experiments/abstract.py -m)")
    df = pd.DataFrame(rows)
    return df.sort_values(["method", "zshape", "radius", "L_max"], kind="stable").reset_index(drop=True)


def edge_sets(root) -> dict:
    """``{job_dir: {(src, dst): L}}`` for every job under ``root``."""
    out = {}
    for path in sorted(Path(root).rglob("metrics.json")):
        data = json.loads(path.read_text())
        out[str(path.parent)] = {(a, b): L for a, b, L in data.get("edges", [])}
    return out


def add_conservatism(df: pd.DataFrame) -> pd.DataFrame:
    """Add ``exact_edges`` and ``conservatism`` = edges found / exact2d edges.

    The exact reference of a row is the ``exact2d`` job with the same
    :data:`GROUP_KEYS`; rows without one get NaN.
    """
    exact = df[df["method"] == "exact2d"].groupby(GROUP_KEYS)["n_edges"].max().rename("exact_edges")
    out = df.join(exact, on=GROUP_KEYS)
    out["conservatism"] = out["n_edges"] / out["exact_edges"]
    return out
