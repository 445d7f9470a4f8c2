"""Plots of a ``radius.json`` (``experiments/radius.py``, :mod:`tubejax.analyses.radius_analysis.report`):
the exact step functions ``n_edges(rho)``, with sweep results on top, and the critical
disturbances of the transitions."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

__all__ = ["load_radius_document", "step_points", "plot_n_edges_curves", "plot_rho_star_histogram",
           "plot_n_edges_vs_L_max"]

_STYLE = {"tube": dict(color="tab:blue"), "openloop": dict(color="tab:red")}


def load_radius_document(path) -> dict:
    """``radius.json`` of a run directory (or the file itself)."""
    p = Path(path)
    return json.loads((p / "radius.json" if p.is_dir() else p).read_text())


def step_points(step: dict, rho_end: float) -> tuple[np.ndarray, np.ndarray]:
    """``(rho, n)`` tracing the step function ``{"rho", "n_edges"}`` over ``[0, rho_end]`` (for
    ``plt.plot``: right-continuous drawing of ``n(rho) = #{rho* >= rho}``)."""
    rho = np.asarray(step["rho"], float)
    n = np.asarray(step["n_edges"], int)
    xs, ys, x0 = [], [], 0.0
    for r, k in zip(rho, n):
        if r > rho_end:
            xs += [x0, rho_end]
            ys += [k, k]
            return np.array(xs), np.array(ys)
        xs += [x0, r]
        ys += [k, k]
        x0 = r
    xs += [x0, rho_end]
    ys += [0, 0]
    return np.array(xs), np.array(ys)


def plot_n_edges_curves(doc: dict, sweep: pd.DataFrame | None = None, rho_end: float | None = None, ax=None):
    """``n_edges(rho)`` of every form in ``doc`` as exact step curves; ``sweep`` (a
    :func:`tubejax.analyses.sweep_results.collect_metrics` table) adds its jobs as points on top: tube and
    open-loop at ``doc``'s ``L_max`` (``Z = box``), and ``exact2d`` (black squares), the most any
    feedback can achieve."""
    ax = ax or plt.subplots(figsize=(6, 4))[1]
    L_max = doc["L_max"]
    if rho_end is None:
        tops = [max(f["n_edges"]["rho"], default=0.0) for f in doc["forms"].values()]
        rho_end = 1.1 * max(tops + [max(doc["radii"], default=0.0), 1e-3])
    unit = doc["disturbance"]["unit"]
    for form, f in doc["forms"].items():
        x, y = step_points(f["n_edges"], rho_end)
        ax.plot(x, y, lw=1.8, label=f"{form}: every radius from one solve", **_STYLE.get(form, {}))
    if sweep is not None and len(sweep):
        s = sweep[sweep["L_max"] == L_max]
        for form in doc["forms"]:
            g = s[(s["method"] == form) & ((s["zshape"] == "box") if form == "tube" else True)]
            g = g.drop_duplicates("radius").sort_values("radius")
            if len(g):
                ax.plot(g["radius"], g["n_edges"], ls="none", marker="o", mfc="none", ms=8,
                        label=f"{form}: sweep jobs", **_STYLE.get(form, {}))
        g = s[s["method"] == "exact2d"].drop_duplicates("radius").sort_values("radius")
        if len(g):
            ax.plot(g["radius"], g["n_edges"], color="k", ls=":", marker="s", ms=5, label="exact2d (sampled radii)")
    ax.set_xlim(0, rho_end)
    ax.set_xlabel(f"disturbance size rho ({unit})")
    ax.set_ylabel("transitions")
    ax.set_title(f"n_edges(rho), L_max = {L_max}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return ax


def plot_rho_star_histogram(doc: dict, bins: int = 30, ax=None):
    """Histogram of the transitions' critical disturbances ``rho*_ij`` (every pair that is an edge at
    ``rho = 0``): how far each transition is from breaking. The requested radii are marked."""
    ax = ax or plt.subplots(figsize=(6, 4))[1]
    vals = {form: np.array([v for v in f["pairs"]["rho_star"] if v is not None and v >= 0], float)
            for form, f in doc["forms"].items()}
    top = max([float(v.max()) for v in vals.values() if v.size] + [1e-3])
    edges = np.linspace(0, top * 1.0001, bins + 1)
    for form, v in vals.items():
        ax.hist(v, bins=edges, alpha=0.55, label=f"{form} ({v.size} transitions)", **_STYLE.get(form, {}))
    for r in doc["radii"]:
        ax.axvline(r, color="k", lw=0.8, ls="--")
    ax.set_xlabel(f"critical disturbance rho* ({doc['disturbance']['unit']})")
    ax.set_ylabel("transitions")
    ax.set_title("how far each transition is from breaking")
    ax.legend(fontsize=8)
    return ax


def plot_n_edges_vs_L_max(doc: dict, form: str = "tube", ax=None):
    """``n_edges`` against ``L_max`` at each reported radius, from the one run (solid: the
    verified systems written at requested radii; dotted: the curves)."""
    ax = ax or plt.subplots(figsize=(6, 4))[1]
    f = doc["forms"][form]["n_edges_vs_L_max"]
    cmap = plt.get_cmap("viridis")
    for k, (r, n) in enumerate(zip(f["radii"], f["n_edges"])):
        src = f.get("source", ["curve"] * len(f["radii"]))[k]
        ax.plot(f["L_max"], n, marker="o", ls="-" if src == "system" else ":",
                color=cmap(k / max(len(f["radii"]) - 1, 1)), label=f"rho = {r:g} ({src})")
    ax.set_xlabel("L_max")
    ax.set_ylabel("transitions")
    ax.set_title(f"{form}: every L_max from one solve")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return ax
