"""Standard plots of a parameter sweep (a table from :func:`tubejax.analysis.collect_metrics`)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import pandas as pd

__all__ = ["plot_edges_vs_radius", "plot_conservatism", "plot_runtime", "plot_lmax"]


def _series(ax, df, y, by):
    for key, g in df.groupby(by):
        g = g.sort_values("radius")
        name = key if isinstance(key, str) else " / ".join(map(str, key))
        ax.plot(g["radius"], g[y], marker="o", label=name)
    ax.set_xlabel("disturbance size r")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def plot_edges_vs_radius(df: pd.DataFrame, ax=None):
    """Transitions found against ``r``, one line per method and Z shape (largest ``L_max``)."""
    ax = ax or plt.subplots(figsize=(5, 3.5))[1]
    sub = df[df["L_max"] == df["L_max"].max()]
    _series(ax, sub, "n_edges", ["method", "zshape"])
    ax.set_ylabel("transitions")
    ax.set_title(f"transitions vs disturbance (L_max = {sub['L_max'].max()})")
    return ax


def plot_conservatism(df: pd.DataFrame, ax=None):
    """Edges found / exact2d edges against ``r`` (needs :func:`add_conservatism`)."""
    ax = ax or plt.subplots(figsize=(5, 3.5))[1]
    sub = df[(df["method"] != "exact2d") & df["conservatism"].notna() & (df["L_max"] == df["L_max"].max())]
    _series(ax, sub, "conservatism", ["method", "zshape"])
    ax.set_ylim(-0.05, 1.05)
    ax.set_ylabel("edges / exact edges")
    ax.set_title("conservatism against the exact 2-D reference")
    return ax


def plot_lmax(df: pd.DataFrame, ax=None):
    """Transitions against ``L_max``, one line per method at each radius."""
    ax = ax or plt.subplots(figsize=(5, 3.5))[1]
    for key, g in df.groupby(["method", "radius"]):
        g = g.groupby("L_max")["n_edges"].max()
        ax.plot(g.index, g.values, marker="o", label=f"{key[0]}, r={key[1]:g}")
    ax.set_xlabel("L_max")
    ax.set_ylabel("transitions")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title("effect of L_max")
    return ax


def plot_runtime(df: pd.DataFrame, ax=None):
    """Wall time per job against the number of LPs solved, by method and solver."""
    ax = ax or plt.subplots(figsize=(5, 3.5))[1]
    for key, g in df.groupby(["method", "solver"]):
        ax.scatter(g["n_lps"], g["seconds"], label=" / ".join(key), s=18)
    ax.set_xlabel("LPs solved")
    ax.set_ylabel("seconds")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("runtime")
    return ax
