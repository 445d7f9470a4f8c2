"""Plots of a ``radius.json`` (``experiments/radius.py``): the exact step functions ``n_edges(rho)``, with
sweep results on top, and the critical disturbances of the transitions."""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from ...lp.evidence.registry import exact_references, series_name, tube_methods
from .style import series_colour

__all__ = ["load_radius_document", "plot_n_edges_curves", "plot_rho_star_histogram",
           "plot_n_edges_vs_L_max", "doc_zshape"]


def doc_zshape(doc: dict) -> str:
    """The kind of ``Z`` of a ``radius.json`` (from its inputs record; ``'box'`` when it has none)."""
    return str((((doc.get("inputs") or {}).get("zshape")) or {}).get("kind", "box"))


def _name(form: str, doc: dict) -> str:
    """A form as the sweep plots name it (``'tube (box)'``, ``'openloop'``)."""
    return series_name(form, doc_zshape(doc))


def _style(form: str, doc: dict) -> dict:
    return dict(color=series_colour(form, doc_zshape(doc)))


def load_radius_document(path) -> dict:
    """``radius.json`` of a run directory (or the file itself)."""
    p = Path(path)
    return json.loads((p / "radius.json" if p.is_dir() else p).read_text())


def _stairs(step: dict, rho_end: float) -> tuple[np.ndarray, np.ndarray]:
    """``(values (m+1,), edges (m+2,))`` of the step function ``{"rho" (ascending), "n_edges"}`` over
    ``[0, rho_end]``, for ``ax.stairs``: ``n(rho) = #{rho* >= rho}`` is ``n_edges[k]`` up to ``rho[k]``."""
    rho, n = np.asarray(step["rho"], float), np.asarray(step["n_edges"], int)
    m = int(np.searchsorted(rho, rho_end, side="right"))            # the breakpoints in [0, rho_end]
    return np.append(n[:m], n[m] if m < len(n) else 0), np.concatenate([[0.0], rho[:m], [rho_end]])


def plot_n_edges_curves(doc: dict, sweep: pd.DataFrame | None = None, rho_end: float | None = None, ax=None,
                        forms=None, exact: bool = True):
    """``n_edges(rho)`` of every form in ``doc`` (or of ``forms``) as exact step curves, in its series' colour
    (call it once per run for several kinds of ``Z``); ``sweep`` (a
    :func:`~tubejax.analyses.sweep_results.collect_metrics` table) adds its jobs at ``doc``'s ``L_max`` and
    ``Z`` as points, and with ``exact`` the exact2d ones."""
    ax = ax or plt.subplots(figsize=(6, 4))[1]
    forms = list(doc["forms"]) if forms is None else [f for f in forms if f in doc["forms"]]
    z = doc_zshape(doc)
    L_max = doc["L_max"]
    if rho_end is None:
        tops = [max(f["n_edges"]["rho"], default=0.0) for f in doc["forms"].values()]
        rho_end = 1.1 * max(tops + [max(doc["radii"], default=0.0), 1e-3])
    unit = doc["disturbance"]["unit"]
    for form in forms:
        ax.stairs(*_stairs(doc["forms"][form]["n_edges"], rho_end), baseline=None, lw=1.8,
                  label=f"{_name(form, doc)}, exact curve", **_style(form, doc))
    if sweep is not None and len(sweep):
        s = sweep[sweep["L_max"] == L_max]
        for form in forms:
            g = s[(s["method"] == form) & ((s["zshape"] == z) if form in tube_methods() else True)]
            g = g.drop_duplicates("radius").sort_values("radius")
            if len(g):
                ax.plot(g["radius"], g["n_edges"], ls="none", marker="o", mfc="none", ms=8,
                        label=f"{_name(form, doc)}, sweep jobs", **_style(form, doc))
        g = s[s["method"].isin(exact_references())].drop_duplicates("radius").sort_values("radius")
        if exact and len(g):
            ax.plot(g["radius"], g["n_edges"], color="k", ls=":", marker="s", ms=5, label="exact2d (sampled radii)")
    ax.set(xlim=(0, rho_end), xlabel=f"disturbance size rho ({unit})", ylabel="transitions",
           title=f"n_edges(rho), L_max = {L_max}")
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
        ax.hist(v, bins=edges, alpha=0.55, label=f"{_name(form, doc)} ({v.size} transitions)", **_style(form, doc))
    for r in doc["radii"]:
        ax.axvline(r, color="k", lw=0.8, ls="--")
    ax.set(xlabel=f"critical disturbance rho* ({doc['disturbance']['unit']})", ylabel="transitions",
           title="how far each transition is from breaking")
    ax.legend(fontsize=8)
    return ax


def plot_n_edges_vs_L_max(doc: dict, form: str = "tube", ax=None):
    """``n_edges`` against ``L_max`` at each reported radius, from the one run (solid: the verified systems
    written at requested radii; dotted: read off the curves), radii dark to light (viridis)."""
    ax = ax or plt.subplots(figsize=(6, 4))[1]
    f = doc["forms"][form]["n_edges_vs_L_max"]
    cmap = plt.get_cmap("viridis")
    names = {"system": "verified system written", "curve": "read off the curves"}
    for k, (r, n) in enumerate(zip(f["radii"], f["n_edges"])):
        src = f.get("source", ["curve"] * len(f["radii"]))[k]
        ax.plot(f["L_max"], n, marker="o", ls="-" if src == "system" else ":",
                color=cmap(0.75 * k / max(len(f["radii"]) - 1, 1)), label=f"rho = {r:g}: {names.get(src, src)}")
    ax.set(xlabel="L_max", ylabel="transitions", title=f"{_name(form, doc)}: every L_max from one solve")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return ax
