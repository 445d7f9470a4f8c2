"""The transition graph over the map: every edge an arrow coloured by ``L`` (up to :data:`MAX_EDGES`,
:func:`plot_transition_graph`), else one arrow per pair of blocks of cells
(:func:`plot_transition_blocks`); a layered 3-D workspace gets a panel per layer
(:func:`plot_transition_graph_layers`).
"""

from __future__ import annotations

import math

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import FancyArrowPatch

from .figures import discrete_colours, plot_workspace
from .layers import layer_edges, layer_of, plot_workspace_layers
from .constraint_layer import system_constraints
from .style import _ax, paper_style

__all__ = ["MAX_EDGES", "plot_transition_graph", "plot_transition_blocks", "plot_transition_graph_layers",
           "cell_blocks"]

#: Above this many edges (in a panel) the graph is drawn by blocks of cells.
MAX_EDGES = 400


def _edges(ts, cmap) -> tuple[list, list, dict]:
    """``(edges, Ls, colour)``: ``(src, dst, L)`` per edge, their ``L`` and one colour per value of ``L``."""
    edges = [(int(e.src), int(e.dst), int(e.L)) for e in ts.edges]
    Ls = [L for _, _, L in edges]
    return edges, Ls, discrete_colours(Ls, cmap)


def _arrows(ax, C: np.ndarray, edges, colour: dict) -> None:
    """One arrow per edge ``(src, dst, L)`` between centroids ``C (N, 2)``; a pair used both ways bends."""
    pairs = {(a, b) for a, b, _ in edges}
    for a, b, L in edges:
        rad = 0.15 if (b, a) in pairs else 0.0
        ax.add_patch(FancyArrowPatch(C[a], C[b], arrowstyle="-|>", mutation_scale=7,
                                     connectionstyle=f"arc3,rad={rad}", color=colour[L],
                                     linewidth=0.6, alpha=0.8, shrinkA=3, shrinkB=3, zorder=6))


def cell_blocks(C: np.ndarray, lo, hi, per_side: int) -> tuple[np.ndarray, float]:
    """Square blocks of cells, ``per_side`` along the longer side of ``[lo, hi]``: ``(block (N,), side)``, the
    block of each centroid ``C (N, 2)`` (row-major) and the blocks' side."""
    lo, hi = np.asarray(lo, float)[:2], np.asarray(hi, float)[:2]
    side = float(np.max(hi - lo)) / max(int(per_side), 1)
    n = np.maximum(np.ceil((hi - lo) / side - 1e-9).astype(int), 1)
    ij = np.clip(np.floor((C - lo) / side).astype(int), 0, n - 1)
    return ij[:, 1] * n[0] + ij[:, 0], side


def _blocks(ax, C: np.ndarray, edges, colour: dict, lo, hi, per_side: int | None = None) -> str:
    """Draw ``edges`` aggregated over blocks of cells; returns the title's description."""
    per_side = per_side or max(2, round(math.sqrt(len(C) / 9)))       # about nine cells a block
    block, side = cell_blocks(C, lo, hi, per_side)
    centre = {b: C[block == b].mean(axis=0) for b in np.unique(block)}
    between, inside = {}, {}
    for a, b, L in edges:
        key = (int(block[a]), int(block[b]))
        if key[0] == key[1]:
            inside[key[0]] = inside.get(key[0], 0) + 1
        else:
            n, least = between.get(key, (0, L))
            between[key] = (n + 1, min(least, L))
    top = max([n for n, _ in between.values()] + [1])
    for (a, b), (n, least) in between.items():
        rad = 0.12 if (b, a) in between else 0.0
        ax.add_patch(FancyArrowPatch(centre[a], centre[b], arrowstyle="-|>", mutation_scale=8,
                                     connectionstyle=f"arc3,rad={rad}", color=colour[least],
                                     linewidth=0.6 + 3.4 * n / top, alpha=0.85, shrinkA=4, shrinkB=4, zorder=6))
    if inside:
        big = max(inside.values())
        xy = np.array([centre[b] for b in inside])
        ax.scatter(xy[:, 0], xy[:, 1], s=[8 + 80 * inside[b] / big for b in inside], color="0.45", alpha=0.7,
                   zorder=7, edgecolors="white", linewidths=0.4)
    for k, line in enumerate((ax.axvline, ax.axhline)):
        for v in np.arange(float(lo[k]) + side, float(hi[k]) - 1e-9, side):
            line(v, color="0.35", lw=0.8, ls="--", zorder=1.5)
    return f"by blocks of {side:g} x {side:g}"


def _legend(ax_or_fig, colour: dict, Ls: list, aggregated: bool, extra=()):
    counts = {v: Ls.count(v) for v in colour}
    handles = [Line2D([], [], color=c, lw=2, label=f"{v} ({counts[v]})") for v, c in colour.items()]
    if aggregated:
        handles += [Line2D([], [], color="0.3", lw=0.6, label="few transitions"),
                    Line2D([], [], color="0.3", lw=4.0, label="most transitions"),
                    Line2D([], [], ls="none", marker="o", color="0.45", label="within a block")]
    handles += list(extra)
    title = "least L (edges)" if aggregated else "L (edges)"
    ax_or_fig.legend(handles=handles, title=title, loc="upper left", borderaxespad=0.0, fontsize=7, title_fontsize=8,
                     frameon=False, ncol=math.ceil(len(handles) / 20),   # a figure: beside the panels
                     bbox_to_anchor=(1.0 if hasattr(ax_or_fig, "legends") else 1.02, 1.0))


def _graph_setup(ts, ax, cmap, workspace: bool, labels: bool):
    """Fresh or given axes with the workspace drawn: ``(ax, d, C (N, 2), edges, Ls, colour)``."""
    ax = _ax(ax)
    d = ts.decomposition
    if workspace:
        plot_workspace(d, ax, labels=labels, state_constraints=system_constraints(ts))
    return ax, d, np.array([P.centroid[:2] for P in d.cells]), *_edges(ts, cmap)


def _graph_finish(ax, ts, colour: dict, Ls: list, aggregated: bool, title: str):
    if colour:
        _legend(ax, colour, Ls, aggregated)
    lo, hi = ts.decomposition.bounds()
    ax.set(xlim=(lo[0] - 0.1, hi[0] + 0.1), ylim=(lo[1] - 0.1, hi[1] + 0.1), aspect="equal")
    ax.set_title(title, fontsize=None if paper_style() else 9)
    return ax


def plot_transition_graph(ts, ax=None, cmap="plasma", workspace: bool = True, max_edges: int = MAX_EDGES):
    """The transition system: nodes at cell centroids, arrows in one colour per value of ``L`` (legend beside
    the axes, with the count of each); above ``max_edges`` edges by blocks (:func:`plot_transition_blocks`)."""
    if ts.n_edges > max_edges:
        return plot_transition_blocks(ts, ax, cmap, workspace)
    ax, d, C, edges, Ls, colour = _graph_setup(ts, ax, cmap, workspace, False)
    _arrows(ax, C, edges, colour)
    ax.scatter(C[:, 0], C[:, 1], s=14, color="k", zorder=7)
    _labels(ax, d, C)
    return _graph_finish(ax, ts, colour, Ls, False, f"{ts.n_cells} cells, {ts.n_edges} transitions")


def _labels(ax, d, C, ids=None):
    ids = range(len(C)) if ids is None else ids
    for i, c in zip(ids, C):
        if d.labels[i] is not None:
            ax.annotate(str(d.labels[i]), c, xytext=(3, 3), textcoords="offset points",
                        fontsize=8, fontweight="bold", zorder=8)


def plot_transition_blocks(ts, ax=None, cmap="plasma", workspace: bool = True, per_side: int | None = None):
    """The transition graph over square blocks of cells (about nine cells a block, or ``per_side`` along the
    longer side; dashed): an arrow per ordered pair of blocks, a grey dot per block (module docstring)."""
    ax, d, C, edges, Ls, colour = _graph_setup(ts, ax, cmap, workspace, True)
    how = _blocks(ax, C, edges, colour, *d.bounds(), per_side)
    return _graph_finish(ax, ts, colour, Ls, True, f"{ts.n_cells} cells, {ts.n_edges} transitions, {how}")


def plot_transition_graph_layers(ts, axes=None, cmap="plasma", panel_width: float = 4.0,
                                 max_edges: int = MAX_EDGES) -> list:
    """The transition graph of a layered 3-D workspace, one panel per layer (bottom first).

    Edges within a layer are drawn in its panel (by blocks above ``max_edges``); edges to another layer
    are a triangle at their source (``^`` above the node, ``v`` below), as large as their number.
    Returns the axes, one per layer; the triangles are the collections with gid ``'up'`` / ``'down'``.
    """
    d = ts.decomposition
    zs = layer_edges(d)
    axes = plot_workspace_layers(d, axes, labels=False, state_constraints=system_constraints(ts),
                                 panel_width=panel_width)
    C3 = np.array([P.centroid[:3] for P in d.cells])
    layer = layer_of(C3[:, 2], zs)
    C = C3[:, :2]
    edges, Ls, colour = _edges(ts, cmap)
    aggregated = False
    lo, hi = d.bounds()
    blo, bhi = d.cell_boxes()
    step = float(np.median(bhi[:, 1] - blo[:, 1]))
    for k, ax in enumerate(axes):
        mine = [(a, b, L) for a, b, L in edges if layer[a] == k and layer[b] == k]
        if len(mine) > max_edges:
            _blocks(ax, C, mine, colour, lo, hi)
            aggregated = True
        else:
            _arrows(ax, C, mine, colour)
        ids = np.flatnonzero(layer == k)
        ax.scatter(C[ids, 0], C[ids, 1], s=10, color="k", zorder=7)
        _labels(ax, d, C[ids], ids)
        for up, marker in ((True, "^"), (False, "v")):
            src = np.array([a for a, b, _ in edges if layer[a] == k and (layer[b] > k if up else layer[b] < k)], int)
            if src.size:
                cells, n = np.unique(src, return_counts=True)
                dy = (0.18 if up else -0.18) * step                  # up above the node, down below it
                ax.scatter(C[cells, 0], C[cells, 1] + dy, marker=marker, s=12 + 8 * n, color="0.25",
                           edgecolors="white", linewidths=0.4, zorder=8, gid="up" if up else "down")
    fig = axes[0].figure
    extra = [Line2D([], [], ls="none", marker="^", color="0.25", label="to the layer above"),
             Line2D([], [], ls="none", marker="v", color="0.25", label="to the layer below")]
    if colour:
        _legend(fig, colour, Ls, aggregated, extra)
    fig.suptitle(f"{ts.n_cells} cells, {ts.n_edges} transitions", fontsize=9)
    return axes
