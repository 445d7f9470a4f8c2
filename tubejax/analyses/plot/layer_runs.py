"""Figs. 7 and 8 for a layered 3-D workspace, one panel per layer (:mod:`~tubejax.analyses.plot.layers`).

In 2-D a voxel map's layers overlay, and a run seems to cross an obstacle on another floor. Here each
part of a run is drawn in its layer's panel, triangles where it moves up or down; the runs drawn, the
colours, the shading and the titles are those of the 2-D figures (title over, legend below the panels).
"""

from __future__ import annotations

import numpy as np
from matplotlib.collections import PolyCollection
from matplotlib.patches import FancyArrowPatch

from ..spec.regions import region_pieces
from .layers import (PathStyle, crossing_handles, crossings, draw_paths, drawn_space, layer_axes, layer_edges,
                     layer_of, plot_workspace_layers, slab_pieces)
from .spec import region_styles, spec_legend, spec_title, spec_violations
from .constraint_layer import system_constraints
from .trajectories import (RUN_COLOURS, RunsStyle, _chosen, _density, _direction_arrows, _run_handles, _run_lines,
                           drawn_caption, runs_title)

__all__ = ["plot_trajectories_layers", "plot_specification_layers"]

#: Inches above and below the panels for the title and the legend.
_EXTRA = 0.6


def _panels(decomp, axes, panel_width: float, state_constraints: dict) -> tuple:
    """``(axes, fig, edges)``: the layers of ``decomp`` drawn on ``axes`` (default: a new figure, :data:`_EXTRA`
    inches more for the title and the legend) with their labels aside, and the layer boundaries."""
    axes = list(layer_axes(decomp, panel_width, _EXTRA)[1] if axes is None else axes)
    axes = plot_workspace_layers(decomp, axes, state_constraints=state_constraints, labels_aside=True)
    return axes, axes[0].figure, layer_edges(decomp)


def _points_by_layer(axes, edges, X: np.ndarray, **style):
    """Dots at the states ``X (k, 3)``, each in its layer's panel."""
    X = X[np.isfinite(X).all(1)]
    where = layer_of(X[:, 2], edges)
    for k, ax in enumerate(axes):
        if (where == k).any():
            ax.plot(X[where == k, 0], X[where == k, 1], ".", **style)


def _runs(axes, edges, decomp, X_all, chosen: tuple, density: bool, color, ends=("start", "end")) -> tuple:
    """:func:`~tubejax.analyses.plot.trajectories._draw_runs` in layers: shading when not all runs are drawn,
    the runs ``chosen = (bad_all, idx, seed)`` as lines in ``color`` (violating ones over them), dots at their
    ``ends``. Returns ``(bad (drawn,), the directions drawn runs move between layers in (True up), caption)``."""
    bad_all, idx, seed = chosen
    lo, hi = (b[:2] for b in decomp.bounds())
    if density and len(idx) < len(X_all):
        P = X_all.reshape(-1, 3)
        P = P[np.isfinite(P).all(1)]
        where = layer_of(P[:, 2], edges)
        for k, ax in enumerate(axes):
            if (where == k).any():
                _density(ax, P[where == k][None, :, :2], lo, hi)
    X, bad = X_all[idx], bad_all[idx]
    for runs, style in zip((~bad, bad), _run_lines(color)):
        if runs.any():
            draw_paths(axes, edges, X[runs], PathStyle(**style))
    for end, k in (("start", 0), ("end", -1)):
        if end in ends and len(X):
            _points_by_layer(axes, edges, X[:, k], color=RUN_COLOURS[end], ms=3, zorder=8)
    caption = drawn_caption(len(idx), len(X_all), seed, int(bad_all.sum()), density)
    return bad, {up for x in X for _, _, up in crossings(x, edges)}, caption


def _legend(fig, handles):
    if handles:
        fig.legend(handles=handles, loc="outside lower center", ncol=min(len(handles), 6), fontsize=7,
                   frameon=False)


def plot_trajectories_layers(decomp, result, axes=None, runs: RunsStyle = RunsStyle(),
                             state_constraints: dict | None = None, panel_width: float = 4.0) -> list:
    """Fig. 7 (:func:`~tubejax.analyses.plot.trajectories.plot_trajectories`) for a layered 3-D ``decomp``.

    ``result.trajectories (runs, T+1, 3)``; ``axes`` one per layer (default: a new figure of ``panel_width``
    inches a panel); ``runs`` and ``state_constraints`` as in 2-D. Returns the axes, one per layer.
    """
    if state_constraints is None:
        state_constraints = getattr(result, "state_constraints", None) or {}
    axes, fig, edges = _panels(decomp, axes, panel_width, state_constraints)
    X_all = np.asarray(result.trajectories, float)[:, :, :3]
    bad, moves, caption = _runs(axes, edges, decomp, X_all, _chosen(result, runs.max_runs, runs.seed), runs.density,
                                runs.color, ("start", "end") if runs.show_start_end else ())
    dots = runs.show_start_end and len(bad)
    finite = np.isfinite(X_all).all(axis=(1, 2))
    drawn = []
    if runs.arrows and finite.any():
        lo, hi = (b[:2] for b in decomp.bounds())
        scale = float(np.max(hi - lo))
        mean = X_all[finite].mean(axis=0)
        for k, ax in enumerate(axes):
            for piece in slab_pieces(mean, edges[k], edges[k + 1], k, edges):   # as often as in 2-D
                drawn += _direction_arrows(ax, piece[:, :2], scale, least=1)
    _legend(fig, _run_handles(dots, drawn, bad.any()) + crossing_handles(runs.color, moves))
    fig.suptitle(runs_title(result, caption), fontsize=9)
    return axes


def _regions(axes, edges, decomp, labels, **style):
    """The regions of ``labels`` (3-D boxes), each piece as its ``(x_1, x_2)`` rectangle in every layer it overlaps."""
    pieces = [P for _, P in region_pieces(decomp, sorted(labels))]
    for k, ax in enumerate(axes):
        polys = []
        for P in pieces:
            lo, hi = P.bounding_box()
            if min(hi[2], edges[k + 1]) - max(lo[2], edges[k]) > 0:
                polys.append(np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]]))
        if polys:
            ax.add_collection(PolyCollection(polys, zorder=3, **style))


def _plan(axes, edges, decomp, cells) -> set:
    """The plan's cell path, centroid to centroid, cut at the layers: an arrowhead where a part
    ends at a cell, triangles where it moves between layers; returns the directions it moves in."""
    C = np.array([decomp.cells[c].centroid for c in cells])
    moves = set()
    for a, b in zip(C[:-1], C[1:]):
        seg = np.array([a, b])
        for k, ax in enumerate(axes):
            for piece in slab_pieces(seg, edges[k], edges[k + 1], k, edges):
                p, q = piece[0, :2], piece[-1, :2]
                if np.linalg.norm(q - p) <= 1e-12:
                    continue
                head = "-|>" if np.allclose(piece[-1], b) else "-"
                ax.add_patch(FancyArrowPatch(p, q, arrowstyle=head, mutation_scale=9, color="black",
                                             linewidth=1.2, shrinkA=0, shrinkB=4 if head != "-" else 0,
                                             zorder=9))
        for k, x, up in crossings(seg, edges):
            moves.add(up)
            for j in (k - 1, k):
                axes[j].plot(x[0], x[1], "^" if up else "v", ls="none", ms=7, color="black",
                             markeredgecolor="white", markeredgewidth=0.6, zorder=10.5)
    k0 = int(layer_of(C[0, 2], edges))
    axes[k0].plot(C[:1, 0], C[:1, 1], "o", color="black", ms=5, zorder=10)
    return moves


def plot_specification_layers(ts, spec_plan, simulation=None, axes=None, max_runs: int | None = 50,
                              seed: int | None = None, density: bool = True, panel_width: float = 4.0) -> list:
    """Fig. 8 (:func:`~tubejax.analyses.plot.spec.plot_specification`) for ``ts`` over a layered decomposition.

    The plan's cell path is cut where it moves between layers (a black triangle there in both panels; a
    move straight up or down shows as the triangle alone). The arguments are those of the 2-D figure,
    ``axes`` one per layer (default: a new figure of ``panel_width`` inches a panel). Returns the axes.
    """
    d, positions, cell_of = drawn_space(ts.decomposition)       # a lifted state space: its map
    constraints = system_constraints(ts) if d is ts.decomposition else {}
    axes, fig, edges = _panels(d, axes, panel_width, constraints)
    for name, labels, style in region_styles(spec_plan):
        _regions(axes, edges, d, labels, label=name, **style)
    caption, moves = None, set()
    if simulation is not None:
        X_all = np.asarray(simulation.trajectories, float)[:, :, list(positions)]
        chosen = _chosen(simulation.result, max_runs, seed, spec_violations(simulation))
        _, moves, caption = _runs(axes, edges, d, X_all, chosen, density, RUN_COLOURS["run"], ("start",))
    moves |= _plan(axes, edges, d, cell_of[np.asarray(spec_plan.plan.cells, dtype=int)])
    _legend(fig, spec_legend(spec_plan, simulation is not None) + crossing_handles("0.2", moves))
    fig.suptitle(spec_title(spec_plan, simulation, caption), fontsize=8)
    return axes
