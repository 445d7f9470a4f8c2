"""3-D workspaces of boxes (:func:`is_layered`: a voxel map, a 3-D box grid) drawn one panel per layer.

Cut at every height where a box begins or ends (:func:`layer_edges`), each layer is drawn exactly by
the 2-D figure of its slice (:func:`layer_slice`); paths are cut at the layer boundaries
(:func:`slab_pieces`, :func:`draw_paths`), a triangle where one moves between layers.
"""

from __future__ import annotations

import dataclasses
import math

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.lines import Line2D

from ...model.geometry import Polytope
from ...model.workspace import CellDecomposition
from ...model.workspace.lookahead import position_view
from .figures import _draw_obstacles, _frame, plot_workspace
from .constraint_layer import plot_state_constraints

__all__ = ["drawn_space", "project_runs", "is_layered", "layer_edges", "layer_of", "layer_slice", "layer_axes",
           "layer_title", "plot_workspace_layers", "slab_pieces", "crossings", "PathStyle", "draw_paths",
           "crossing_handles"]

#: Heights closer than this (relative to the block's height) are one layer boundary.
_ZTOL = 1e-9


def drawn_space(decomp):
    """What the layered and 3-D figures draw for ``decomp``: ``(map, axes, cell_of (N,))``: ``decomp``, ``(0, 1, 2)``
    and the identity, or for a lifted decomposition its map, the position axes and each cell's map cell."""
    view = position_view(decomp)
    if view is None:
        return decomp, (0, 1, 2), np.arange(decomp.n_cells)
    return view.base, tuple(view.axes), np.asarray(view.base_cell)


def project_runs(result, axes):
    """``result`` with its trajectories on ``axes`` only, ``(runs, T+1, len(axes))`` (the rest as it is)."""
    if tuple(axes) == tuple(range(np.asarray(result.trajectories).shape[-1])):
        return result
    return dataclasses.replace(result, trajectories=np.asarray(result.trajectories, float)[:, :, list(axes)])


def is_layered(decomp) -> bool:
    """Whether ``decomp`` is a 3-D workspace of boxes (every cell and obstacle an axis-aligned box),
    drawn layer by layer (a voxel map, whose ``grid`` holds ``(layer, row, col)``, or a 3-D box grid)."""
    return decomp.dim == 3 and all(isinstance(P, Polytope) and P.is_box for P in (*decomp.cells, *decomp.obstacles))


def _block_bounds(decomp) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)``: the box around the cells and the domain (when given)."""
    lo, hi = decomp.bounds()
    if decomp.domain is not None:
        dlo, dhi = decomp.domain.bounding_box()
        lo, hi = np.minimum(lo, dlo), np.maximum(hi, dhi)
    return lo, hi


def _z_range(P) -> tuple[float, float]:
    lo, hi = P.bounding_box()
    return float(lo[2]), float(hi[2])


def layer_edges(decomp) -> np.ndarray:
    """The layer boundaries: every height where a cell, an obstacle or the domain begins or ends,
    sorted, shape ``(K + 1,)`` (a voxel map of ``K`` layers: ``0, 1, ..., K``)."""
    lo, hi = decomp.cell_boxes()
    z = [lo[:, 2], hi[:, 2]] + [np.array(_z_range(o)) for o in decomp.obstacles]
    if decomp.domain is not None:
        z.append(np.array(_z_range(decomp.domain)))
    z = np.unique(np.concatenate(z))
    keep = np.concatenate([[True], np.diff(z) > _ZTOL * max(float(z[-1] - z[0]), 1.0)])
    return z[keep]


def layer_of(z, edges: np.ndarray) -> np.ndarray:
    """The layer of each height ``z`` (any shape): ``k`` with ``z`` in ``[z_k, z_{k+1})`` (the top
    layer closed; heights outside the block go to the nearest layer)."""
    return np.clip(np.searchsorted(edges, np.asarray(z, float), side="right") - 1, 0, len(edges) - 2)


def layer_title(k: int, edges: np.ndarray) -> str:
    """``'layer 1 (bottom): x_3 in [0, 1]'``: a panel's title (layers numbered from 1, bottom up)."""
    K = len(edges) - 1
    where = " (bottom)" if k == 0 and K > 1 else " (top)" if k == K - 1 and K > 1 else ""
    return f"layer {k + 1}{where}: $x_3 \\in [{edges[k]:g}, {edges[k + 1]:g}]$"


def layer_slice(decomp, k: int, edges: np.ndarray):
    """Layer ``k`` of a layered workspace as a 2-D workspace: ``(ids (N_k,), cells, obstacles)``, the cells
    spanning the layer, their ``(x_1, x_2)`` rectangles with labels and obstacles as a ``CellDecomposition``
    (``None`` without a free cell there), and the 2-D rectangles of the obstacles spanning it."""
    zm = 0.5 * (edges[k] + edges[k + 1])
    lo, hi = decomp.cell_boxes()
    ids = np.flatnonzero((lo[:, 2] < zm) & (zm < hi[:, 2]))
    obstacles = []
    for o in decomp.obstacles:
        a, b = o.bounding_box()
        if a[2] < zm < b[2]:
            obstacles.append(Polytope.box(a[:2], b[:2]))
    if not len(ids):
        return ids, None, obstacles
    cells = tuple(Polytope.box(lo[i, :2], hi[i, :2]) for i in ids)
    labels = tuple(decomp.labels[i] for i in ids)
    grid = None if decomp.grid is None else np.asarray(decomp.grid)[ids]
    return ids, CellDecomposition(cells, labels, tuple(obstacles), grid, f"{decomp.name} layer {k + 1}"), obstacles


def layer_axes(decomp, panel_width: float = 4.0, extra_height: float = 0.0):
    """``(fig, axes)``: one panel per layer of the layered ``decomp``, bottom first in reading order, three a row
    at most (``ceil(sqrt(K))`` from four layers on), ``panel_width`` inches wide (the height follows the map's
    aspect), ``extra_height`` inches more for a title and a legend."""
    K = len(layer_edges(decomp)) - 1
    ncols = K if K <= 3 else math.ceil(math.sqrt(K))
    nrows = math.ceil(K / ncols)
    lo, hi = decomp.bounds()
    ratio = float(np.clip((hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-12), 0.3, 1.5))
    fig, grid = plt.subplots(nrows, ncols, squeeze=False, layout="constrained",
                             figsize=(ncols * panel_width, nrows * (panel_width * ratio + 0.5) + extra_height))
    for ax in grid.flat[K:]:
        fig.delaxes(ax)
    return fig, list(grid.flat[:K])


def plot_workspace_layers(decomp, axes=None, labels: bool = True, state_constraints: dict | None = None,
                          panel_width: float = 4.0, obstacle_color="black", labels_aside: bool = False) -> list:
    """Fig. 5 for a layered 3-D workspace: one panel per layer with its cells, labels and obstacles.

    Parameters
    ----------
    decomp : CellDecomposition
        Layered (:func:`is_layered`).
    axes : sequence of Axes, optional
        One per layer, bottom first (default: :func:`layer_axes` of ``panel_width``).
    labels, state_constraints, labels_aside :
        As in :func:`~tubejax.analyses.plot.figures.plot_workspace` (the constraints' rows in ``(x_1, x_2)``).

    Returns
    -------
    list of Axes
        One per layer; ``axes[k]`` holds exactly the obstacles that span layer ``k`` (one patch each).
    """
    edges = layer_edges(decomp)
    if axes is None:
        _, axes = layer_axes(decomp, panel_width)
    axes = list(axes)
    if len(axes) != len(edges) - 1:
        raise ValueError(f"expected one axes per layer ({len(edges) - 1}), got {len(axes)}")
    lo, hi = _block_bounds(decomp)
    for k, ax in enumerate(axes):
        _, sl, obstacles = layer_slice(decomp, k, edges)
        if sl is not None:
            plot_workspace(sl, ax, labels=labels, obstacle_color=obstacle_color, labels_aside=labels_aside)
        else:                                   # no free cell: the obstacles alone
            _draw_obstacles(ax, obstacles, obstacle_color)
        _frame(ax, lo, hi, 0.02)
        plot_state_constraints(ax, state_constraints or {})
        ax.set_title(layer_title(k, edges), fontsize=9)
    return axes


def slab_pieces(path: np.ndarray, z0: float, z1: float, layer: int | None = None, edges=None) -> list:
    """The parts of a polyline that lie in the slab ``z0 <= x_3 <= z1``.

    Parameters
    ----------
    path : ndarray, shape (T+1, 3)
        States joined by straight segments; a segment with a non-finite end is left out.
    z0, z1 : float
    layer, edges : int and ndarray, optional
        A horizontal segment on a boundary belongs to the layer :func:`layer_of` gives its height;
        without them, to every slab it touches.

    Returns
    -------
    list of ndarray, shape (m, 3)
        Polylines (``m >= 2``) cut where they cross ``z0`` or ``z1``; parts of zero length left out.
    """
    P = np.asarray(path, float)
    a, b = P[:-1], P[1:]
    ok = np.isfinite(a).all(1) & np.isfinite(b).all(1)
    dz = b[:, 2] - a[:, 2]
    flat = np.abs(dz) <= 1e-15 * max(abs(z1 - z0), 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t0, t1 = (z0 - a[:, 2]) / dz, (z1 - a[:, 2]) / dz
    inside = (z0 <= a[:, 2]) & (a[:, 2] <= z1)
    if layer is not None and edges is not None:
        inside = layer_of(a[:, 2], edges) == layer
    lo = np.where(flat, np.where(inside, 0.0, 1.0), np.maximum(np.minimum(t0, t1), 0.0))
    hi = np.where(flat, np.where(inside, 1.0, 0.0), np.minimum(np.maximum(t0, t1), 1.0))
    keep = ok & (hi > lo)
    out, joined = [], -2                     # joined: the segment whose part reached its end
    for i in np.flatnonzero(keep):
        p, q = a[i] + lo[i] * (b[i] - a[i]), a[i] + hi[i] * (b[i] - a[i])
        if joined == i - 1 and lo[i] == 0.0:
            out[-1].append(q)
        else:
            out.append([p, q])
        joined = i if hi[i] == 1.0 else -2
    return [np.array(o) for o in out]


def crossings(path: np.ndarray, edges: np.ndarray) -> list:
    """Where a polyline moves between layers: ``[(k, point (3,), up), ...]``, one per layer
    boundary ``edges[k]`` crossed (between layers ``k - 1`` and ``k``), in the order travelled."""
    P = np.asarray(path, float)
    a, b = P[:-1], P[1:]
    ok = np.isfinite(a).all(1) & np.isfinite(b).all(1)
    la, lb = layer_of(a[:, 2], edges), layer_of(b[:, 2], edges)
    out = []
    for i in np.flatnonzero(ok & (la != lb)):
        up = bool(lb[i] > la[i])
        ks = range(la[i] + 1, lb[i] + 1) if up else range(la[i], lb[i], -1)
        for k in ks:
            t = (edges[k] - a[i, 2]) / (b[i, 2] - a[i, 2])
            out.append((int(k), a[i] + t * (b[i] - a[i]), up))
    return out


@dataclasses.dataclass(frozen=True)
class PathStyle:
    """How :func:`draw_paths` draws its paths: the lines' ``color``, ``linewidth``, ``alpha``, ``zorder`` and
    ``label``; ``marker_size`` of the triangles where a path moves between layers (``0``: none)."""

    color: object = "tab:blue"
    linewidth: float = 0.6
    alpha: float = 0.5
    zorder: float = 6
    marker_size: float = 4.0
    label: str | None = None


def draw_paths(axes, edges: np.ndarray, paths, style: PathStyle = PathStyle()) -> list:
    """Draw the 3-D polylines ``paths`` (each ``(T+1, 3)``) on ``axes`` (one per layer of ``edges``,
    :func:`layer_edges`): each part in its layer's panel, a triangle where one moves between layers
    (``^`` up, ``v`` down, in both panels). Returns how many parts each panel got."""
    paths = list(paths)
    counts = []
    for k, ax in enumerate(axes):
        pieces = [p[:, :2] for path in paths for p in slab_pieces(path, edges[k], edges[k + 1], k, edges)]
        counts.append(len(pieces))
        if pieces:
            ax.add_collection(LineCollection(pieces, colors=style.color, linewidths=style.linewidth,
                                             alpha=style.alpha, zorder=style.zorder, label=style.label))
    if style.marker_size > 0:
        marks = {(k, up): [] for k in range(len(axes)) for up in (True, False)}
        for path in paths:
            for k, x, up in crossings(path, edges):
                marks[k - 1, up].append(x)
                marks[k, up].append(x)
        for (k, up), xs in marks.items():
            if xs:
                xs = np.array(xs)
                axes[k].plot(xs[:, 0], xs[:, 1], "^" if up else "v", ls="none", ms=style.marker_size,
                             color=style.color, markeredgecolor="white", markeredgewidth=0.4,
                             zorder=style.zorder + 2.5)
    return counts


def crossing_handles(color="0.2", directions=(True, False)) -> list:
    """Legend entries for :func:`draw_paths`' triangles: ``True`` up, ``False`` down."""
    names = {True: ("^", "moves up a layer"), False: ("v", "moves down a layer")}
    return [Line2D([], [], ls="none", marker=names[up][0], color=color, label=names[up][1])
            for up in (True, False) if up in set(directions)]
