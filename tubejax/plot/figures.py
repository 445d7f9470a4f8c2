"""Figures of the paper (Figs. 5-7) and of the transition graph, with matplotlib.

All functions draw 2-D workspaces (the first two coordinates are used when
``n > 2``), accept an optional ``ax`` and return the ``Axes`` they drew on.
Nothing calls ``plt.show``; use :func:`save_figure` to write PNG and PDF.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import shapely
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.patches import FancyArrowPatch, Polygon as MplPolygon

from ..geometry import Polytope, convex_hull_of

__all__ = ["plot_workspace", "plot_tube", "plot_trajectories", "plot_transition_graph",
           "save_figure", "new_axes"]


def new_axes(figsize=(6, 6)):
    """A fresh ``(fig, ax)`` pair (Agg backend)."""
    fig, ax = plt.subplots(figsize=figsize)
    return fig, ax


def _ax(ax, figsize=(6, 6)):
    if ax is None:
        _, ax = new_axes(figsize)
    return ax


def _poly2d(P: Polytope) -> np.ndarray:
    """Vertices of a 2-D polytope in counter-clockwise order, shape ``(n_v, 2)``."""
    V = np.asarray(P.vertices, float)[:, :2]
    c = V.mean(0)
    return V[np.argsort(np.arctan2(V[:, 1] - c[1], V[:, 0] - c[0]))]


def _obstacle_polys(o):
    """Exterior rings (and holes) of an obstacle as lists of ``(k, 2)`` arrays."""
    if isinstance(o, Polytope):
        return [_poly2d(o)], []
    ext, holes = [], []
    for g in getattr(o, "geoms", [o]):
        if isinstance(g, shapely.Polygon) and not g.is_empty:
            ext.append(np.asarray(g.exterior.coords))
            holes += [np.asarray(r.coords) for r in g.interiors]
    return ext, holes


def plot_workspace(decomp, ax=None, labels: bool = True, cell_ids: bool = False,
                   obstacle_color="black"):
    """Fig. 5: cells outlined, region labels written, obstacles filled.

    Parameters
    ----------
    decomp : CellDecomposition
    ax : matplotlib Axes, optional
    labels : bool
        Write each labelled cell's label at its centroid.
    cell_ids : bool
        Write every cell's id (small, grey).

    Returns
    -------
    Axes
    """
    ax = _ax(ax)
    polys = [_poly2d(P) for P in decomp.cells]
    ax.add_collection(PolyCollection(polys, facecolors="white", edgecolors="0.6",
                                     linewidths=0.6, zorder=1))
    for o in decomp.obstacles:
        ext, holes = _obstacle_polys(o)
        for r in ext:
            ax.add_patch(MplPolygon(r, closed=True, facecolor=obstacle_color,
                                    edgecolor=obstacle_color, zorder=2))
        for r in holes:
            ax.add_patch(MplPolygon(r, closed=True, facecolor="white", edgecolor="0.6", zorder=2))
    for i, P in enumerate(decomp.cells):
        c = P.centroid[:2]
        if labels and decomp.labels[i] is not None:
            ax.text(c[0], c[1], str(decomp.labels[i]), ha="center", va="center",
                    fontsize=12, fontweight="bold", zorder=9,
                    bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.7))
        elif cell_ids:
            ax.text(c[0], c[1], str(i), ha="center", va="center", fontsize=6, color="0.5",
                    zorder=5)
    lo, hi = decomp.bounds()
    pad = 0.02 * float(np.max(hi[:2] - lo[:2]))
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("$x_1$")
    ax.set_ylabel("$x_2$")
    return ax


def plot_tube(ts, edge_k: int, ax=None, workspace: bool = False):
    """Fig. 6: ``P_i``, ``P_j``, the hull ``P_ij`` and the tube sets ``Q_1 .. Q_L`` of an edge.

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
        plot_workspace(d, ax)
    hull = convex_hull_of(Pi, Pj)
    ax.add_patch(MplPolygon(_poly2d(hull), closed=True, facecolor="none", edgecolor="0.3",
                            linestyle="--", linewidth=1.2, label="$P_{ij}$", zorder=3))
    ax.add_patch(MplPolygon(_poly2d(Pi), closed=True, facecolor="tab:green", alpha=0.25,
                            edgecolor="tab:green", linewidth=1.5, label=f"$P_i$ (cell {e.src})",
                            zorder=3))
    ax.add_patch(MplPolygon(_poly2d(Pj), closed=True, facecolor="tab:orange", alpha=0.25,
                            edgecolor="tab:orange", linewidth=1.5, label=f"$P_j$ (cell {e.dst})",
                            zorder=3))
    q = ts.tubes[int(edge_k)].vertices(ts.z_of(e.src, e.dst), Pi)        # (L+1, n_v, n)
    cmap = plt.get_cmap("viridis")
    L = int(e.L)
    for l in range(1, L + 1):
        Q = Polytope.from_vertices(q[l])
        ax.add_patch(MplPolygon(_poly2d(Q), closed=True, facecolor="none",
                                edgecolor=cmap(l / max(L, 1)), linewidth=1.3, zorder=4,
                                label="$Q_\\ell$, $\\ell=1..L$" if l == 1 else None))
        c = Q.centroid[:2]
        ax.text(c[0], c[1], str(l), fontsize=7, ha="center", va="center",
                color=cmap(l / max(L, 1)), zorder=5)
    if not workspace:
        lo, hi = hull.bounding_box()
        pad = 0.1 * float(np.max(hi[:2] - lo[:2]))
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_aspect("equal")
    ax.set_title(f"edge {e.src} $\\to$ {e.dst}: L = {L}, margin = {e.margin:.3g}")
    ax.legend(loc="best", fontsize=7)
    return ax


def plot_trajectories(decomp, result, ax=None, max_runs: int | None = 200, color="tab:blue",
                      show_start_end: bool = True):
    """Fig. 7: closed-loop trajectories over the workspace.

    Runs with an obstacle entry or a tube exit are drawn in red; initial states are
    green dots, final states purple dots.

    Parameters
    ----------
    decomp : CellDecomposition
    result : SimulationResult
        (or anything with ``trajectories (runs, T+1, n)`` and optional ``tube_exit``,
        ``obstacle_entry`` flags)
    max_runs : int or None
        Draw at most this many runs (the first ones).

    Returns
    -------
    Axes
    """
    ax = plot_workspace(decomp, ax)
    X = np.asarray(result.trajectories)[:, :, :2]
    if max_runs is not None:
        X = X[:max_runs]
    bad = np.zeros(len(X), bool)
    for flag in ("tube_exit", "obstacle_entry"):
        if hasattr(result, flag):
            bad |= np.asarray(getattr(result, flag))[:len(X)]
    good_lines = LineCollection(list(X[~bad]), colors=color, linewidths=0.6, alpha=0.5, zorder=6)
    ax.add_collection(good_lines)
    if bad.any():
        ax.add_collection(LineCollection(list(X[bad]), colors="red", linewidths=0.8, alpha=0.8,
                                         zorder=7))
    if show_start_end and len(X):
        ax.plot(X[:, 0, 0], X[:, 0, 1], ".", color="tab:green", ms=3, zorder=8)
        ax.plot(X[:, -1, 0], X[:, -1, 1], ".", color="tab:purple", ms=3, zorder=8)
    s = result.summary() if hasattr(result, "summary") else None
    if s:
        ax.set_title(f"{s['runs']} runs ({s['mode']}): {s['obstacle_entries']} obstacle entries, "
                     f"{s['tube_exits']} tube exits", fontsize=9)
    return ax


def plot_transition_graph(ts, ax=None, cmap="plasma", workspace: bool = True):
    """The transition system: nodes at cell centroids, arrows coloured by ``L``.

    Returns
    -------
    Axes
    """
    ax = _ax(ax)
    d = ts.decomposition
    if workspace:
        plot_workspace(d, ax, labels=False)
    C = np.array([P.centroid[:2] for P in d.cells])
    Ls = np.array([e.L for e in ts.edges]) if ts.edges else np.array([1])
    norm = matplotlib.colors.Normalize(vmin=Ls.min(), vmax=max(Ls.max(), Ls.min() + 1))
    cm = plt.get_cmap(cmap)
    pairs = {(e.src, e.dst) for e in ts.edges}
    for e in ts.edges:
        a, b = C[e.src], C[e.dst]
        rad = 0.15 if (e.dst, e.src) in pairs else 0.0
        ax.add_patch(FancyArrowPatch(a, b, arrowstyle="-|>", mutation_scale=7,
                                     connectionstyle=f"arc3,rad={rad}", color=cm(norm(e.L)),
                                     linewidth=0.6, alpha=0.8, shrinkA=3, shrinkB=3, zorder=6))
    ax.scatter(C[:, 0], C[:, 1], s=14, color="k", zorder=7)
    for i, c in enumerate(C):
        if d.labels[i] is not None:
            ax.annotate(str(d.labels[i]), c, xytext=(3, 3), textcoords="offset points",
                        fontsize=8, fontweight="bold", zorder=8)
    sm = matplotlib.cm.ScalarMappable(norm=norm, cmap=cm)
    ax.figure.colorbar(sm, ax=ax, label="L (edge cost)", shrink=0.7)
    lo, hi = d.bounds()
    ax.set_xlim(lo[0] - 0.1, hi[0] + 0.1)
    ax.set_ylim(lo[1] - 0.1, hi[1] + 0.1)
    ax.set_aspect("equal")
    ax.set_title(f"{ts.n_cells} cells, {ts.n_edges} transitions", fontsize=9)
    return ax


def save_figure(fig, directory, stem: str, dpi: int = 150) -> tuple[Path, Path]:
    """Write ``directory/<stem>.png`` and ``directory/<stem>.pdf``; returns both paths.

    ``fig`` may also be an ``Axes`` (its figure is saved).
    """
    fig = getattr(fig, "figure", fig) if not hasattr(fig, "savefig") else fig
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    png, pdf = directory / f"{stem}.png", directory / f"{stem}.pdf"
    fig.savefig(png, dpi=dpi, bbox_inches="tight")
    fig.savefig(pdf, bbox_inches="tight")
    return png, pdf
