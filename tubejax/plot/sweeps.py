"""Standard plots of a parameter sweep (a table from :func:`tubejax.analysis.collect_metrics`).

Only the tube method depends on the shape of ``Z``; open-loop and exact2d rows
are merged over ``zshape``. exact2d (the most any feedback can achieve) is drawn
as a dashed black reference line.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import pandas as pd

__all__ = ["series_table", "plot_edges_vs_radius", "plot_conservatism", "plot_runtime", "plot_lmax"]

_STYLE = {"exact2d": dict(color="k", ls="--", marker="s"), "openloop": dict(color="tab:red", marker="v")}


def series_table(df: pd.DataFrame) -> pd.DataFrame:
    """Add a ``series`` column: ``'tube (box)'``, ``'tube (diamond)'``, ``'openloop'``, ``'exact2d'``,
    and drop rows repeated over ``zshape`` for the methods that ignore it."""
    out = df.copy()
    out["series"] = [f"tube ({z})" if m == "tube" else m for m, z in zip(out["method"], out["zshape"])]
    keys = [k for k in ("series", "workspace", "system", "disturbance", "radius", "L_max", "solver")
            if k in out]
    return out.drop_duplicates(subset=keys)


def _lines(ax, df, y):
    for name, g in series_table(df).groupby("series", sort=True):
        g = g.sort_values("radius")
        ax.plot(g["radius"], g[y], label=name, **_STYLE.get(name, dict(marker="o")))
    ax.set_xlabel("disturbance size r")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def plot_edges_vs_radius(df: pd.DataFrame, ax=None):
    """Transitions found against ``r``, one line per method (and Z shape for tubes), at the largest ``L_max``."""
    ax = ax or plt.subplots(figsize=(5, 3.5))[1]
    _lines(ax, df[df["L_max"] == df["L_max"].max()], "n_edges")
    ax.set_ylabel("transitions")
    ax.set_title(f"transitions vs disturbance (L_max = {df['L_max'].max()})")
    return ax


def plot_conservatism(df: pd.DataFrame, ax=None):
    """Edges found / exact2d edges against ``r`` (needs :func:`tubejax.analysis.add_conservatism`)."""
    ax = ax or plt.subplots(figsize=(5, 3.5))[1]
    sub = df[(df["method"] != "exact2d") & df["conservatism"].notna() & (df["L_max"] == df["L_max"].max())]
    _lines(ax, sub, "conservatism")
    ax.axhline(1.0, color="k", ls="--", lw=1)
    ax.set_ylim(-0.05, 1.05)
    ax.set_ylabel("edges / exact edges")
    ax.set_title("conservatism against the exact 2-D reference")
    return ax


def plot_lmax(df: pd.DataFrame, ax=None):
    """Transitions against ``L_max``: one colour per radius; solid tube (first Z shape), dashed open-loop."""
    ax = ax or plt.subplots(figsize=(5, 3.5))[1]
    t = series_table(df)
    tube_series = sorted(s for s in t["series"].unique() if s.startswith("tube"))
    radii = sorted(t["radius"].unique())
    cmap = plt.get_cmap("viridis")
    for k, r in enumerate(radii):
        col = cmap(k / max(len(radii) - 1, 1))
        for name, ls in ((tube_series[0] if tube_series else None, "-"), ("openloop", "--")):
            g = t[(t["series"] == name) & (t["radius"] == r)].sort_values("L_max")
            if len(g):
                ax.plot(g["L_max"], g["n_edges"], ls=ls, marker="o", color=col,
                        label=f"{name}, r={r:g}")
    ax.set_xlabel("L_max")
    ax.set_ylabel("transitions")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("effect of L_max (solid: tube, dashed: open-loop)")
    return ax


def plot_runtime(df: pd.DataFrame, ax=None):
    """Wall time per job against the number of LPs (or exact pair checks) solved."""
    ax = ax or plt.subplots(figsize=(5, 3.5))[1]
    for key, g in df.groupby(["method", "solver"]):
        ax.scatter(g["n_lps"], g["seconds"], label=" / ".join(key), s=18)
    ax.set_xlabel("problems solved")
    ax.set_ylabel("seconds")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("runtime")
    return ax
