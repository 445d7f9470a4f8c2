"""The transition graph over the map: every edge an arrow, or blocks of cells when there are many.

A graph of a few hundred edges reads edge by edge (:func:`plot_transition_graph`: nodes at the
cells' centroids, arrows coloured by ``L``). Above :data:`MAX_EDGES` it becomes a hairball, so
the map is cut into square blocks of cells and one arrow joins two blocks, as wide as the number
of transitions between them and coloured by the least ``L`` among them; transitions inside a
block are a grey dot, as large as their number (:func:`plot_transition_blocks`). A layered 3-D
workspace (a voxel map) is drawn one panel per layer (:func:`plot_transition_graph_layers`):
the edges within a layer in its panel, an edge to another layer as a triangle at its source
(``^`` up, ``v`` down), never projected onto ``(x_1, x_2)`` over the other layers.
"""

from __future__ import annotations

import math

import numpy as np
from matplotlib.lines import Line2D
from matplotlib.patches import FancyArrowPatch

from .figures import discrete_colours, plot_workspace
from .layers import layer_axes, layer_edges, layer_of, plot_workspace_layers
from .state_constraints import system_constraints
from .style import _ax, paper_style

__all__ = ["MAX_EDGES", "plot_transition_graph", "plot_transition_blocks", "plot_transition_graph_layers",
           "cell_blocks"]

#: Above this many edges (in a panel) the graph is drawn by blocks of cells.
MAX_EDGES = 400


def _edges(ts) -> list[tuple[int, int, int]]:
    return [(int(e.src), int(e.dst), int(e.L)) for e in ts.edges]


def _arrows(ax, C: np.ndarray, edges, colour: dict) -> None:
    """One arrow per edge ``(src, dst, L)`` between centroids ``C (N, 2)``; a pair used both ways bends."""
    pairs = {(a, b) for a, b, _ in edges}
    for a, b, L in edges:
        rad = 0.15 if (b, a) in pairs else 0.0
        ax.add_patch(FancyArrowPatch(C[a], C[b], arrowstyle="-|>", mutation_scale=7,
                                     connectionstyle=f"arc3,rad={rad}", color=colour[L],
                                     linewidth=0.6, alpha=0.8, shrinkA=3, shrinkB=3, zorder=6))


def cell_blocks(C: np.ndarray, lo, hi, per_side: int) -> tuple[np.ndarray, float]:
    """Square blocks of cells: ``per_side`` blocks along the longer side of ``[lo, hi]``.

    Returns
    -------
    block : ndarray of int, shape (N,)
        The block of each centroid ``C (N, 2)`` (row-major over the blocks).
    side : float
        The blocks' side.
    """
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
    lo2 = np.asarray(lo, float)[:2]
    hi2 = np.asarray(hi, float)[:2]
    for x in np.arange(lo2[0] + side, hi2[0] - 1e-9, side):
        ax.axvline(x, color="0.35", lw=0.8, ls="--", zorder=1.5)
    for y in np.arange(lo2[1] + side, hi2[1] - 1e-9, side):
        ax.axhline(y, color="0.35", lw=0.8, ls="--", zorder=1.5)
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
    kw = dict(handles=handles, title=title, loc="upper left", borderaxespad=0.0, fontsize=7, title_fontsize=8,
              frameon=False, ncol=math.ceil(len(handles) / 20))
    if hasattr(ax_or_fig, "legends"):                       # a figure: beside the panels
        ax_or_fig.legend(bbox_to_anchor=(1.0, 1.0), **kw)
    else:
        ax_or_fig.legend(bbox_to_anchor=(1.02, 1.0), **kw)


def plot_transition_graph(ts, ax=None, cmap="plasma", workspace: bool = True, max_edges: int = MAX_EDGES):
    """The transition system: nodes at cell centroids, arrows coloured by ``L``.

    ``L`` takes few values, so its colours are discrete: one colour per value of ``L``,
    named in a legend (with the number of edges of each) beside the axes. With more than
    ``max_edges`` edges the graph is drawn by blocks of cells (:func:`plot_transition_blocks`).

    Returns
    -------
    Axes
    """
    if ts.n_edges > max_edges:
        return plot_transition_blocks(ts, ax, cmap, workspace)
    ax = _ax(ax)
    d = ts.decomposition
    if workspace:
        plot_workspace(d, ax, labels=False, state_constraints=system_constraints(ts))
    C = np.array([P.centroid[:2] for P in d.cells])
    edges = _edges(ts)
    Ls = [L for _, _, L in edges]
    colour = discrete_colours(Ls, cmap)
    _arrows(ax, C, edges, colour)
    ax.scatter(C[:, 0], C[:, 1], s=14, color="k", zorder=7)
    _labels(ax, d, C)
    if colour:
        _legend(ax, colour, Ls, False)
    _limits(ax, d)
    ax.set_title(f"{ts.n_cells} cells, {ts.n_edges} transitions", fontsize=None if paper_style() else 9)
    return ax


def _labels(ax, d, C, ids=None):
    ids = range(len(C)) if ids is None else ids
    for i, c in zip(ids, C):
        if d.labels[i] is not None:
            ax.annotate(str(d.labels[i]), c, xytext=(3, 3), textcoords="offset points",
                        fontsize=8, fontweight="bold", zorder=8)


def _limits(ax, d):
    lo, hi = d.bounds()
    ax.set_xlim(lo[0] - 0.1, hi[0] + 0.1)
    ax.set_ylim(lo[1] - 0.1, hi[1] + 0.1)
    ax.set_aspect("equal")


def plot_transition_blocks(ts, ax=None, cmap="plasma", workspace: bool = True, per_side: int | None = None):
    """The transition graph aggregated over square blocks of cells (about nine cells a block, or
    ``per_side`` blocks along the longer side): one arrow per ordered pair of blocks, as wide as
    the number of transitions between them, coloured by the least ``L`` among them; a grey dot
    per block as large as the number of transitions inside it. The blocks are dashed.

    Returns
    -------
    Axes
    """
    ax = _ax(ax)
    d = ts.decomposition
    if workspace:
        plot_workspace(d, ax, labels=True, state_constraints=system_constraints(ts))
    C = np.array([P.centroid[:2] for P in d.cells])
    edges = _edges(ts)
    Ls = [L for _, _, L in edges]
    colour = discrete_colours(Ls, cmap)
    lo, hi = d.bounds()
    how = _blocks(ax, C, edges, colour, lo, hi, per_side)
    if colour:
        _legend(ax, colour, Ls, True)
    _limits(ax, d)
    ax.set_title(f"{ts.n_cells} cells, {ts.n_edges} transitions, {how}", fontsize=None if paper_style() else 9)
    return ax


def plot_transition_graph_layers(ts, axes=None, cmap="plasma", panel_width: float = 4.0,
                                 max_edges: int = MAX_EDGES) -> list:
    """The transition graph of a layered 3-D workspace, one panel per layer (bottom first).

    The edges between two cells of a layer are drawn in its panel (by blocks of cells when the
    panel has more than ``max_edges``); an edge to a cell of another layer is a triangle at its
    source (just above its node for ``^`` up, below it for ``v`` down), as large as the number of
    such edges, in the panel of the source.

    Returns
    -------
    list of Axes
        One per layer; the triangles are the collections with gid ``'up'`` and ``'down'``.
    """
    d = ts.decomposition
    zs = layer_edges(d)
    if axes is None:
        fig, axes = layer_axes(d, panel_width)
    axes = plot_workspace_layers(d, axes, labels=False, state_constraints=system_constraints(ts))
    C3 = np.array([P.centroid[:3] for P in d.cells])
    layer = layer_of(C3[:, 2], zs)
    C = C3[:, :2]
    edges = _edges(ts)
    Ls = [L for _, _, L in edges]
    colour = discrete_colours(Ls, cmap)
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
