"""Figures over a 2-D map (the first two coordinates when ``n > 2``): the workspace (Fig. 5) and a tube (Fig. 6).

Each function takes an optional ``ax`` and returns the ``Axes`` it drew on; the system's state
constraints are hatched outside (:mod:`~tubejax.analyses.plot.constraint_layer`).
"""

from __future__ import annotations

import math

import matplotlib.pyplot as plt
import numpy as np
import shapely
from matplotlib import patheffects
from matplotlib.collections import PolyCollection
from matplotlib.patches import Polygon as MplPolygon

from ...model.geometry import Polytope, convex_hull_of
from .constraint_layer import plot_state_constraints, system_constraints
from .style import PALETTE, _ax, number, paper_style

__all__ = ["plot_workspace", "plot_tube", "discrete_colours", "tube_title"]


def _poly2d(P: Polytope) -> np.ndarray:
    """Vertices of a 2-D polytope in counter-clockwise order, shape ``(n_v, 2)``."""
    V = np.asarray(P.vertices, float)[:, :2]
    c = V.mean(0)
    return V[np.argsort(np.arctan2(V[:, 1] - c[1], V[:, 0] - c[0]))]


def _draw_obstacles(ax, obstacles, color) -> None:
    """Each obstacle (a polytope or shapely polygons) filled in ``color``, its holes white."""
    for o in obstacles:
        parts = [g for g in getattr(o, "geoms", [o]) if isinstance(g, shapely.Polygon) and not g.is_empty]
        rings = ([(_poly2d(o), color, color)] if isinstance(o, Polytope) else
                 [(g.exterior.coords, color, color) for g in parts] + [(r.coords, "white", "0.6") for g in parts
                                                                      for r in g.interiors])
        for r, face, edge in rings:
            ax.add_patch(MplPolygon(np.asarray(r), closed=True, facecolor=face, edgecolor=edge, zorder=2))


def plot_workspace(decomp, ax=None, labels: bool = True, cell_ids: bool = False,
                   obstacle_color="black", state_constraints: dict | None = None, labels_aside: bool = False):
    """Fig. 5: cells outlined, region labels written, obstacles filled, state constraints hatched.

    Parameters
    ----------
    decomp : CellDecomposition
    ax : matplotlib Axes, optional
    labels : bool
        Write each labelled cell's label at its centroid.
    cell_ids : bool
        Write every cell's id (small, grey).
    state_constraints : dict, optional
        ``{name: Halfspaces}`` (e.g. ``system.state_constraints``): hatched outside, over the
        workspace's view (:func:`~tubejax.analyses.plot.constraint_layer.plot_state_constraints`).
    labels_aside : bool
        Labels in their cells' upper left corners, outlined: they hide no path through the centre (runs' figures).

    Returns
    -------
    Axes
    """
    ax = _ax(ax)
    polys = [_poly2d(P) for P in decomp.cells]
    ax.add_collection(PolyCollection(polys, facecolors="white", edgecolors="0.6",
                                     linewidths=0.6, zorder=1))
    _draw_obstacles(ax, decomp.obstacles, obstacle_color)
    for i, P in enumerate(decomp.cells):
        c = P.centroid[:2]
        if labels and decomp.labels[i] is not None and labels_aside:
            lo, hi = P.bounding_box()
            ax.text(lo[0] + 0.06 * (hi[0] - lo[0]), hi[1] - 0.06 * (hi[1] - lo[1]), str(decomp.labels[i]),
                    ha="left", va="top", fontsize=10, fontweight="bold", zorder=9,
                    path_effects=[patheffects.withStroke(linewidth=2.5, foreground="white")])
        elif labels and decomp.labels[i] is not None:
            ax.text(c[0], c[1], str(decomp.labels[i]), ha="center", va="center",
                    fontsize=12, fontweight="bold", zorder=9,
                    bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.7))
        elif cell_ids:
            ax.text(c[0], c[1], str(i), ha="center", va="center", fontsize=6, color="0.5",
                    zorder=5)
    _frame(ax, *decomp.bounds(), 0.02)
    plot_state_constraints(ax, state_constraints or {})
    return ax


def plot_tube(ts, edge_k: int, ax=None, workspace: bool = False):
    """Fig. 6: ``P_i``, ``P_j``, the hull ``P_ij`` and the tube sets ``Q_1 .. Q_L`` of an edge.

    The legend stands right of the axes, so it covers none of the sets.

    Parameters
    ----------
    ts : TransitionSystem
    edge_k : int
        Index into ``ts.edges``.
    ax : Axes, optional
    workspace : bool
        Also draw the whole workspace underneath.

    Returns
    -------
    Axes
    """
    ax = _ax(ax)
    e = ts.edges[int(edge_k)]
    d = ts.decomposition
    Pi, Pj = d.cells[e.src], d.cells[e.dst]
    if workspace:
        plot_workspace(d, ax, state_constraints=system_constraints(ts))
    hull = convex_hull_of(Pi, Pj)
    ax.add_patch(MplPolygon(_poly2d(hull), closed=True, facecolor="none", edgecolor="0.3",
                            linestyle="--", linewidth=1.2, label="$P_{ij}$", zorder=3))
    for P, c, name in ((Pi, "green", f"$P_i${_cell_name(d, e.src)}"), (Pj, "orange", f"$P_j${_cell_name(d, e.dst)}")):
        ax.add_patch(MplPolygon(_poly2d(P), closed=True, facecolor=PALETTE[c], alpha=0.25, edgecolor=PALETTE[c],
                                linewidth=1.5, label=name, zorder=3))
    q = ts.tubes[int(edge_k)].vertices(ts.z_of(e.src, e.dst), Pi)        # (L+1, n_v, n)
    cmap = plt.get_cmap("viridis")
    L = int(e.L)
    every = max(1, math.ceil(L / 10))                      # at most about ten step numbers, the last one always
    for l in range(1, L + 1):
        Q = Polytope.from_vertices(q[l])
        ax.add_patch(MplPolygon(_poly2d(Q), closed=True, facecolor="none",
                                edgecolor=cmap(0.85 * l / max(L, 1)), linewidth=1.3, zorder=4,
                                label="$Q_\\ell$, $\\ell=1..L$" if l == 1 else None))
        if l % every == 0 or l == L or l == 1:
            c = Q.centroid[:2]
            ax.text(c[0], c[1], str(l), fontsize=9, fontweight="bold", ha="center", va="center",
                    color=cmap(0.85 * l / max(L, 1)), zorder=5,
                    path_effects=[patheffects.withStroke(linewidth=2.5, foreground="white")])
    if not workspace:                                      # else plot_workspace framed it
        _frame(ax, *hull.bounding_box(), 0.1)
        plot_state_constraints(ax, system_constraints(ts))
    ax.set_title(tube_title(e))
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize=8, frameon=False)
    return ax


def _frame(ax, lo, hi, pad: float) -> None:
    """Limits ``[lo, hi]`` (the first two coordinates) grown by ``pad`` times the longer side, equal aspect,
    axes labelled ``x_1``, ``x_2``."""
    pad = pad * float(np.max(np.asarray(hi)[:2] - np.asarray(lo)[:2]))
    ax.set(xlim=(lo[0] - pad, hi[0] + pad), ylim=(lo[1] - pad, hi[1] + pad), xlabel="$x_1$", ylabel="$x_2$",
           aspect="equal")


def tube_title(e) -> str:
    """The title of an edge's tube figure (2-D and 3-D); in the ``paper`` style without cell ids."""
    if paper_style():
        return f"tube $P_i \\to P_j$: $L = {int(e.L)}$, margin {number(e.margin)}"
    return f"edge {e.src} $\\to$ {e.dst}: L = {int(e.L)}, margin = {number(e.margin)}"


def _cell_name(decomp, i: int) -> str:
    """A cell as a legend names it: by its region label when it has one (the paper style names no cell
    ids), else by its id in the draft style."""
    if decomp.labels[i] is not None:
        return f" (region {decomp.labels[i]})"
    return "" if paper_style() else f" (cell {i})"


def discrete_colours(values, cmap="plasma") -> dict:
    """One colour per distinct value of ``values`` (sorted), from ``cmap`` (its pale yellow end left out)."""
    vals = sorted(set(values))
    cm = plt.get_cmap(cmap)
    pos = np.linspace(0.0, 0.8, len(vals)) if len(vals) > 1 else np.zeros(1)
    return {v: cm(float(p)) for v, p in zip(vals, pos)}
