"""The reach-avoid limit beside every method's winning cells (``experiments/conservatism.py``), and the
fraction of the limit each method wins against the disturbance radius (``experiments/aggregate.py``)."""

from __future__ import annotations

import matplotlib.pyplot as plt
import pandas as pd
import shapely
from matplotlib.patches import PathPatch

from ...lp.evidence.registry import series_style
from .figures import plot_workspace
from .constraint_layer import _path

__all__ = ["plot_limit", "plot_fraction_of_limit"]


def _look(series) -> tuple:
    """The colour and line style of a series (``'tube (box)'``, ``'exact2d'``): its method's record's."""
    style = series_style(str(series).split(" ")[0])
    return style.colour, style.line


def plot_limit(decomp, limit, winning: dict, ax=None):
    """The limit shaded, each method's winning set outlined, obstacles and the target drawn.

    Parameters
    ----------
    decomp : CellDecomposition
    limit : ReachAvoidLimit
    winning : dict
        ``{name: WinningSet}`` (the legend shows each name with its fraction of the limit).
    ax : matplotlib Axes, optional

    Returns
    -------
    Axes
    """
    ax = plot_workspace(decomp, ax=ax, labels=True)
    if not limit.geometry.is_empty:
        ax.add_patch(PathPatch(_path(limit.geometry), facecolor="tab:orange", alpha=0.35, edgecolor="tab:orange",
                               linewidth=0.8, zorder=3,
                               label=f"limit ({limit.area:.2f}{'' if limit.converged else ', NOT converged'})"))
    target = shapely.union_all([shapely.Polygon(decomp.cells[c].vertices)
                                for c in decomp.cells_with_label(limit.target)])
    ax.add_patch(PathPatch(_path(target), facecolor="none", edgecolor="black", hatch="xx", linewidth=1.2,
                           zorder=4, label=f"target {limit.target}"))
    for k, (name, win) in enumerate(winning.items()):
        color, ls = _look(name)
        frac = f"{win.area / limit.area:.0%}" if limit.converged and limit.area > 0 else "?"
        if win.geometry.is_empty:
            ax.plot([], [], color=color, ls=ls, label=f"{name}: no cell")
            continue
        ax.add_patch(PathPatch(_path(win.geometry), facecolor="none", edgecolor=color, linestyle=ls,
                               linewidth=1.8 + 0.6 * (len(winning) - k - 1), zorder=5 + k,
                               label=f"{name} ({frac} of the limit)"))
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0)
    return ax


def plot_fraction_of_limit(df: pd.DataFrame, ax=None):
    """``fraction_of_limit`` against ``radius``, one line per ``series`` (and per other ``group``
    column), the limit at 1.

    Parameters
    ----------
    df : pandas.DataFrame
        Columns ``radius``, ``series``, ``fraction_of_limit`` and optionally ``group``.
    """
    ax = ax or plt.subplots(figsize=(5.5, 3.8))[1]
    keys = ["series"] + (["group"] if "group" in df and df["group"].nunique() > 1 else [])
    for name, g in df.groupby(keys, sort=True):
        g = g.sort_values("radius")
        label = " · ".join(str(v) for v in (name if isinstance(name, tuple) else (name,)))
        color, ls = _look(g["series"].iloc[0])
        ax.plot(g["radius"], g["fraction_of_limit"], marker="o", ms=4, color=color if len(keys) == 1 else None,
                ls=ls, label=label)
    ax.axhline(1.0, color="black", lw=1.0, label="limit")
    ax.set(xlabel="disturbance radius $r$", ylabel="winning area / limit area", ylim=(-0.03, 1.05))
    ax.legend(fontsize=7)
    return ax
