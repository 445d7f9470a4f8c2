"""Tubes in 3-D (``mpl_toolkits.mplot3d``): Fig. 6 for a 3-D workspace, and the plan's tubes (Fig. 9).
Every tube set is a translucent solid (:func:`facets`) among nearby obstacles, with a few runs; a
lifted (drone) decomposition is drawn in its position projection (:func:`drawn_space`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import to_rgba
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator
from mpl_toolkits.mplot3d.art3d import Poly3DCollection

from ...model.geometry import Polytope, convex_hull_of
from .figures import _cell_name, tube_title
from .graph import plot_transition_graph_layers
from .layer_runs import plot_trajectories_layers
from .layers import _block_bounds, drawn_space, plot_workspace_layers, project_runs
from .style import PALETTE, paper_style
from .trajectories import RUN_COLOURS, RunsStyle, _chosen, drawn_caption

__all__ = ["facets", "plot_tube_3d", "plot_plan_tubes_3d", "figures_3d"]

_CMAP = "viridis"
_START, _TARGET = PALETTE["green"], PALETTE["orange"]
#: The default view of the 3-D figures: elevation and azimuth in degrees (``figures.view``).
VIEW = (25.0, -60.0)
_OBSTACLE = (0.15, 0.15, 0.15)
#: Drawing order (the axes do not sort by depth): obstacles at the back, runs and labels in front,
#: so that no translucent obstacle hides a tube set.
_ZORDER = {"obstacle": 1, "hull": 2, "start": 2, "target": 2, "tube": 3, "run": 4, "text": 5}


def facets(P) -> list:
    """The faces of a 3-D polytope ``P`` (``vertices (n_v, 3)``, ``H (n_f, 3)``, ``h (n_f,)``): per facet with at
    least 3 vertices, their indices in order around it (also the faces of ``p + eps P``, ``eps > 0``)."""
    V, H, h = np.asarray(P.vertices, float), np.asarray(P.H, float), np.asarray(P.h, float)
    tol = 1e-9 * max(float(np.ptp(V, axis=0).max()), 1e-300)
    slack = V @ H.T - h                                        # (n_v, n_f)
    out = []
    for f in range(H.shape[0]):
        ix = np.flatnonzero(np.abs(slack[:, f]) <= tol)
        if len(ix) < 3:
            continue
        c = V[ix].mean(axis=0)
        u = V[ix[0]] - c
        u /= np.linalg.norm(u)
        w = np.cross(H[f], u)
        ang = np.arctan2((V[ix] - c) @ w, (V[ix] - c) @ u)
        out.append(ix[np.argsort(ang)])
    return out


@dataclass(frozen=True)
class SolidStyle:
    """A translucent solid (:func:`_solid`): faces ``color`` at ``alpha``, edges at ``edge_alpha``."""

    color: object
    alpha: float
    edge_alpha: float = 0.7
    linestyle: str = "-"
    linewidth: float = 0.6


#: The obstacles: dark, nearly clear faces, faint thin edges.
_OBSTACLE_STYLE = SolidStyle(_OBSTACLE, 0.08, 0.25, linewidth=0.4)


def _solid(ax, V: np.ndarray, faces: list, style: SolidStyle, gid: str) -> Poly3DCollection:
    """A translucent solid: the polygons ``V[ix]`` for ``ix`` in ``faces`` (``V (n_v, 3)``) in ``style``,
    drawn over what is drawn before it (:data:`_ZORDER` of its ``gid``)."""
    poly = Poly3DCollection([V[ix] for ix in faces], facecolors=[to_rgba(style.color, style.alpha)],
                            edgecolors=[to_rgba(style.color, style.edge_alpha)], linewidths=style.linewidth,
                            linestyles=style.linestyle, zorder=_ZORDER[gid])
    poly.set_gid(gid)
    ax.add_collection3d(poly)
    return poly


def _polytope_solid(ax, P, style: SolidStyle, gid: str) -> Poly3DCollection:
    """The 3-D polytope ``P`` (a box: ``Polytope.box(lo, hi)``) as a translucent solid."""
    return _solid(ax, np.asarray(P.vertices, float), facets(P), style, gid)


def _key(colour, label: str, alpha: float = 0.25, edge=None) -> Patch:
    """A legend entry of a translucent solid."""
    return Patch(facecolor=to_rgba(colour, alpha), edgecolor=colour if edge is None else edge, label=label)


def _runs_and_finish(ax, box, title: str, handles: list, result, runs, axes, view):
    """:func:`_runs_3d` (with ``result``; its caption under the ``draft`` title), then :func:`_finish` in ``box``."""
    if result is not None:
        caption = _runs_3d(ax, result, runs, handles, axes)
        if not paper_style():
            title += "\n" + caption
    _finish(ax, *box, title, handles, view=view)
    return ax


def _axes3d(ax, size):
    ax = plt.figure(figsize=size).add_subplot(projection="3d") if ax is None else ax
    ax.computed_zorder = False
    return ax


def _obstacles(ax, decomp, lo, hi) -> int:
    """The obstacles' parts inside the view box ``[lo, hi]`` as translucent dark boxes; returns how
    many (obstacles that are not boxes are drawn whole when they meet the view)."""
    count = 0
    for o in decomp.obstacles:
        a, b = o.bounding_box()
        a2, b2 = np.maximum(a, lo), np.minimum(b, hi)
        if np.any(b2 - a2 <= 0):
            continue
        _polytope_solid(ax, Polytope.box(a2, b2) if o.is_box else o, _OBSTACLE_STYLE, "obstacle")
        count += 1
    return count


def _finish(ax, lo, hi, title: str, handles: list, fontsize: float = 9, view=VIEW):
    """Limits ``[lo, hi]`` at true scale, labels, the view ``(elevation, azimuth)`` in degrees (default
    from the front left and above), the title and the legend (right of the axes)."""
    ax.set(xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]))
    ax.set_box_aspect(np.maximum(hi - lo, 1e-9), zoom=0.9)
    for axis, name in ((ax.xaxis, "$x_1$"), (ax.yaxis, "$x_2$"), (ax.zaxis, "$x_3$")):
        axis.set_major_locator(MaxNLocator(5, steps=[1, 2, 2.5, 5, 10]))
        axis.set_label_text(name)
    ax.view_init(elev=float(view[0]), azim=float(view[1]))
    ax.set_title(title, fontsize=fontsize)
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize=8,
              frameon=False)


def _tube_sets(ts, k: int):
    """Edge ``k``'s tube sets ``Q_1 .. Q_L`` in the drawn space (:func:`drawn_space`): a list of
    ``(vertices (n_v, 3), faces)``, one per set (a lifted state space: the hull of the positions)."""
    e = ts.edges[int(k)]
    Z = ts.z_of(e.src, e.dst)
    q = np.asarray(ts.tubes[int(k)].vertices(Z, ts.decomposition.cells[e.src]), float)   # (L+1, n_v, n)
    _, axes, _ = drawn_space(ts.decomposition)
    if q.shape[-1] == 3:
        return [(V, facets(Z)) for V in q[1:]]
    out = []
    for V in q[1:, :, list(axes)]:
        P = Polytope.from_vertices(V)
        out.append((np.asarray(P.vertices, float), facets(P)))
    return out


def _view(points: np.ndarray, decomp, pad: float):
    """A box around ``points (k, 3)`` grown by ``pad`` and cut to the workspace."""
    wlo, whi = _block_bounds(decomp)
    return np.maximum(points.min(axis=0) - pad, wlo), np.minimum(points.max(axis=0) + pad, whi)


def _cell_pad(decomp) -> float:
    lo, hi = decomp.cell_boxes()
    return 0.5 * float(np.median(np.max(hi - lo, axis=1)))


def plot_tube_3d(ts, edge_k: int, ax=None, size=(7.0, 6.0), view=VIEW):
    """Fig. 6 in 3-D: ``P_i``, ``P_j``, the hull ``P_ij`` and the tube sets ``Q_1 .. Q_L`` of an edge.

    ``Q_l`` translucent solids from dark (``l = 1``) to light (``l = L``), obstacles within half a cell dark.

    Parameters
    ----------
    ts : TransitionSystem
        Over a 3-D decomposition.
    edge_k : int
        Index into ``ts.edges``.
    ax : Axes3D, optional
    size : (float, float)
        Inches, of a new figure.
    view : (float, float)
        Elevation and azimuth in degrees.

    Returns
    -------
    Axes3D
        Its collections with gid ``'tube'`` are the ``L`` tube sets.
    """
    ax = _axes3d(ax, size)
    e = ts.edges[int(edge_k)]
    d, _, cell_of = drawn_space(ts.decomposition)
    Pi, Pj = d.cells[cell_of[e.src]], d.cells[cell_of[e.dst]]
    hull = convex_hull_of(Pi, Pj)
    sets = _tube_sets(ts, edge_k)
    lo, hi = _view(np.vstack([hull.vertices] + [V for V, _ in sets]), d, _cell_pad(d))
    _obstacles(ax, d, lo, hi)
    _polytope_solid(ax, hull, SolidStyle("0.3", 0.0, 0.8, "--", 1.0), "hull")
    _polytope_solid(ax, Pi, SolidStyle(_START, 0.12, linewidth=1.2), "start")
    _polytope_solid(ax, Pj, SolidStyle(_TARGET, 0.12, linewidth=1.2), "target")
    cmap, L = plt.get_cmap(_CMAP), len(sets)
    for l, (V, faces) in enumerate(sets, start=1):
        colour = cmap(0.85 * l / max(L, 1))
        _solid(ax, V, faces, SolidStyle(colour, 0.3, 0.9, linewidth=0.8), "tube")
        c = V.mean(axis=0)
        ax.text(c[0], c[1], c[2], str(l), fontsize=7, ha="center", va="center", color="black",
                zorder=_ZORDER["text"])
    handles = [Patch(facecolor="none", edgecolor="0.3", linestyle="--", label="$P_{ij}$"),
               _key(_START, f"$P_i${_cell_name(ts.decomposition, e.src)}"),
               _key(_TARGET, f"$P_j${_cell_name(ts.decomposition, e.dst)}"),
               _key(cmap(0.4), "$Q_\\ell$, $\\ell=1..L$", 0.3), _key(_OBSTACLE, "obstacle", 0.3)]
    _finish(ax, lo, hi, tube_title(e), handles, view=view)
    return ax


def plot_plan_tubes_3d(ts, plan, result=None, ax=None, runs: RunsStyle = RunsStyle(max_runs=5),
                       size=(8.0, 6.5), view=VIEW, max_sets: int = 40):
    """Fig. 9: the plan's tubes in 3-D, with the obstacles, its start and targets and a few runs.

    Every tube set of the plan is a translucent solid coloured by its time step along the plan (dark
    first); the start cell green, the cells where the plan's segments end orange, with their labels.

    Parameters
    ----------
    ts : TransitionSystem
        Over a 3-D decomposition.
    plan : Plan
    result : SimulationResult, optional
        ``trajectories (runs, T+1, 3)``: the runs ``runs`` chooses are drawn as lines.
    ax, runs, size, view :
        As in :func:`plot_tube_3d` (``runs``: a :class:`RunsStyle`).
    max_sets : int
        A plan of more tube sets draws about this many (every ``k``-th set of each transition, and
        its last one, which holds the next start), so the figure stays readable.

    Returns
    -------
    Axes3D
        Its collections with gid ``'tube'`` are the tube sets drawn (all ``plan.cost`` up to ``max_sets``).
    """
    ax = _axes3d(ax, size)
    d, axes, cell_of = drawn_space(ts.decomposition)
    sets = [_tube_sets(ts, k) for k in plan.edges]
    total = sum(len(Q) for Q in sets)
    start = int(plan.cells[0])
    targets = sorted({int(plan.cells[i]) for i in plan.segment_ends} - {start}) or [int(plan.cells[-1])]
    shown = [d.cells[cell_of[c]].vertices for c in [start, *targets]] + [V for Q in sets for V, _ in Q]
    lo, hi = _view(np.vstack(shown), d, _cell_pad(d))
    _obstacles(ax, d, lo, hi)
    _start_and_targets(ax, d, [cell_of[start]] + [cell_of[t] for t in targets])
    cmap, step = plt.get_cmap(_CMAP), 0
    every = max(1, math.ceil(total / max(int(max_sets), 1)))
    for Q in sets:
        for l, (V, faces) in enumerate(Q, start=1):
            step += 1
            if l % every == 0 or l == len(Q):
                _solid(ax, V, faces, SolidStyle(cmap(0.9 * step / max(total, 1)), 0.3 if every == 1 else 0.2, 0.8),
                       "tube")
    handles = [_key(_START, "start" + _cell_name(ts.decomposition, start)),
               _key(_TARGET, "target" + "s" * (len(targets) > 1)), _key(cmap(0.1), "$Q_\\ell$, first steps", 0.3),
               _key(cmap(0.9), "$Q_\\ell$, last steps", 0.3), _key(_OBSTACLE, "obstacle", 0.3)]
    title = f"plan: {len(plan.edges)} transitions, {total} tube sets ({plan.cost} steps)"
    if every > 1:
        title += f", every {every}th drawn"
    return _runs_and_finish(ax, (lo, hi), title, handles, result, runs, axes, view)


def _start_and_targets(ax, d, cells: list) -> None:
    """The start cell ``cells[0]`` (green) and the target cells (orange) of ``d`` as solids, with their labels."""
    for c, colour, gid in [(cells[0], _START, "start")] + [(t, _TARGET, "target") for t in cells[1:]]:
        P = d.cells[c]
        _polytope_solid(ax, P, SolidStyle(colour, 0.15, linewidth=1.2), gid)
        if d.labels[c] is not None:
            x = P.centroid
            ax.text(x[0], x[1], P.bounding_box()[1][2], str(d.labels[c]), fontsize=11, fontweight="bold",
                    ha="center", va="bottom", zorder=_ZORDER["text"])


def _runs_3d(ax, result, runs: RunsStyle, handles: list, axes=(0, 1, 2)) -> str:
    """The runs ``runs`` chooses as 3-D lines over the state axes ``axes`` (legend entries appended to
    ``handles``); returns the caption saying how many are drawn."""
    X_all = np.asarray(result.trajectories, float)[:, :, list(axes)]
    bad_all, idx, seed = _chosen(result, runs.max_runs, runs.seed)
    for i in idx:
        X = X_all[i]
        ax.plot(X[:, 0], X[:, 1], X[:, 2], color=RUN_COLOURS["violating" if bad_all[i] else "run"],
                linewidth=0.9, alpha=0.9, zorder=_ZORDER["run"])
        ax.scatter(*X[0], color=RUN_COLOURS["start"], s=8, depthshade=False, zorder=_ZORDER["run"])
        ax.scatter(*X[-1], color=RUN_COLOURS["end"], s=8, depthshade=False, zorder=_ZORDER["run"])
    if (~bad_all[idx]).any():
        handles.append(Line2D([], [], color=RUN_COLOURS["run"], label="runs"))
    if bad_all[idx].any():
        handles.append(Line2D([], [], color=RUN_COLOURS["violating"], label="violating run"))
    return drawn_caption(len(idx), len(X_all), seed, int(bad_all.sum()), False)


def figures_3d(ts, plan, result, edge: int, panel_width: float = 4.0, runs: RunsStyle = RunsStyle(),
               size=(6.0, 6.0), view=VIEW) -> list:
    """The figures a run over a layered 3-D workspace writes, as ``[(stem, Figure), ...]``.

    ``fig5_workspace``, ``fig7_trajectories`` and ``transition_graph``: a panel per layer (``panel_width``
    inches); ``fig6_tube``: edge ``edge``'s tube in 3-D; ``fig9_tubes3d``: the plan's tubes with five runs
    (fewer if ``runs.max_runs`` is). ``size``: the 2-D figures' (the 3-D ones are a little wider);
    ``view``: the 3-D figures'. Over a lifted decomposition (a drone) all are drawn in the position
    projection (:func:`drawn_space`), without the transition graph.
    """
    d, axes, _ = drawn_space(ts.decomposition)
    lifted = d is not ts.decomposition
    constraints = {} if lifted else ts.system.state_constraints
    few = 5 if runs.max_runs is None else min(5, runs.max_runs)
    out = [("fig5_workspace", plot_workspace_layers(d, state_constraints=constraints, panel_width=panel_width)),
           ("fig6_tube", plot_tube_3d(ts, edge, size=(1.2 * size[0], size[1]), view=view)),
           ("fig7_trajectories", plot_trajectories_layers(d, project_runs(result, axes), runs=runs,
                                                          panel_width=panel_width)),
           ("fig9_tubes3d", plot_plan_tubes_3d(ts, plan, result, runs=RunsStyle(max_runs=few),
                                               size=(1.35 * size[0], 1.1 * size[1]), view=view))]
    if not lifted:                  # the graph of a lifted space has many cells per voxel: not drawn per layer
        out.append(("transition_graph", plot_transition_graph_layers(ts, panel_width=panel_width)))
    return [(stem, (a[0] if isinstance(a, list) else a).figure) for stem, a in out]
