"""Figures of the paper (Figs. 5-7) and of the transition graph, with matplotlib.

All functions draw 2-D workspaces (the first two coordinates are used when
``n > 2``), accept an optional ``ax`` and return the ``Axes`` they drew on.
Nothing calls ``plt.show``; use :func:`save_figure` to write PNG and PDF (inside
:func:`figure_style`: TrueType fonts in the PDF, as journals ask, instead of Type 3).

Many runs do not become a blob: :func:`plot_trajectories` draws ``max_runs`` of them
(chosen from the seed by :func:`select_runs`, runs violating the guarantee first),
shades where all of them went, and says in its title how many of how many it drew.
Nothing drawn changes a reported number: the figures only read the results.

The system's state constraints (``system.state_constraints``) are drawn wherever the workspace
is, hatched outside, by :func:`~tubejax.analyses.plot.state_constraints.plot_state_constraints`.
"""

from __future__ import annotations

import contextlib
import logging
import math
from pathlib import Path

import matplotlib
import matplotlib.pyplot as plt
import numpy as np
import shapely
from matplotlib.collections import LineCollection, PolyCollection
from matplotlib.lines import Line2D
from matplotlib.patches import FancyArrowPatch, Polygon as MplPolygon

from ...model.geometry import Polytope, convex_hull_of
from .state_constraints import outside_text, plot_state_constraints, system_constraints

__all__ = ["plot_workspace", "plot_tube", "plot_trajectories", "plot_transition_graph",
           "save_figure", "new_axes", "figure_style", "select_runs", "discrete_colours", "drawn_caption",
           "FIGURE_RC"]

#: The settings :func:`figure_style` applies: fonts embedded as TrueType (Type 42), not Type 3.
FIGURE_RC = {"pdf.fonttype": 42, "ps.fonttype": 42}


def figure_style():
    """A context in which figures are drawn and saved in this package's style (:data:`FIGURE_RC`).

    It changes ``matplotlib.rcParams`` only inside the ``with`` block (nothing is set at
    import); :func:`save_figure` saves inside it.

    Examples
    --------
    >>> with figure_style():
    ...     fig.savefig("fig.pdf")          # doctest: +SKIP
    """
    return _quiet_fonts(matplotlib.rc_context(FIGURE_RC))


@contextlib.contextmanager
def _quiet_fonts(rc):
    """``rc`` with fontTools' subsetting messages (one INFO line per table and font, hundreds per
    PDF with TrueType fonts) held at WARNING while inside it."""
    logger = logging.getLogger("fontTools")
    level = logger.level
    logger.setLevel(max(level, logging.WARNING))
    try:
        with rc:
            yield
    finally:
        logger.setLevel(level)


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
                   obstacle_color="black", state_constraints: dict | None = None):
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
        workspace's view (:func:`~tubejax.analyses.plot.state_constraints.plot_state_constraints`).

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
    plot_state_constraints(ax, state_constraints or {})
    return ax


def plot_tube(ts, edge_k: int, ax=None, workspace: bool = False):
    """Fig. 6: ``P_i``, ``P_j``, the hull ``P_ij`` and the tube sets ``Q_1 .. Q_L`` of an edge.

    The axes are labelled ``x_1``, ``x_2``; the legend stands outside the axes (right of
    them), so it covers none of the sets. The system's state constraints are hatched outside
    (:func:`~tubejax.analyses.plot.state_constraints.plot_state_constraints`).

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
                                edgecolor=cmap(0.85 * l / max(L, 1)), linewidth=1.3, zorder=4,
                                label="$Q_\\ell$, $\\ell=1..L$" if l == 1 else None))
        c = Q.centroid[:2]
        ax.text(c[0], c[1], str(l), fontsize=7, ha="center", va="center",
                color=cmap(0.85 * l / max(L, 1)), zorder=5)
    if not workspace:
        lo, hi = hull.bounding_box()
        pad = 0.1 * float(np.max(hi[:2] - lo[:2]))
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)
        ax.set_aspect("equal")
        plot_state_constraints(ax, system_constraints(ts))
    ax.set_xlabel("$x_1$")
    ax.set_ylabel("$x_2$")
    ax.set_title(f"edge {e.src} $\\to$ {e.dst}: L = {L}, margin = {e.margin:.3g}")
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0, fontsize=8, frameon=False)
    return ax


def select_runs(n_runs: int, max_runs: int | None, seed: int = 0, first=None) -> np.ndarray:
    """Which runs a figure draws: at most ``max_runs`` of ``n_runs``, chosen from ``seed``.

    Parameters
    ----------
    n_runs : int
    max_runs : int or None
        ``None`` (or ``>= n_runs``): every run.
    seed : int
        Seeds :func:`numpy.random.default_rng`; the same seed gives the same runs.
    first : array of bool, shape (n_runs,), optional
        Runs taken before any other (e.g. those violating the guarantee), chosen among
        themselves from ``seed`` when there are more than ``max_runs``.

    Returns
    -------
    ndarray of int
        Sorted run indices.
    """
    n_runs = int(n_runs)
    if max_runs is None or max_runs >= n_runs:
        return np.arange(n_runs)
    k = max(int(max_runs), 0)
    rng = np.random.default_rng(int(seed))
    first = np.zeros(n_runs, bool) if first is None else np.asarray(first, bool)
    pri, rest = np.flatnonzero(first), np.flatnonzero(~first)
    if len(pri) >= k:
        return np.sort(rng.choice(pri, size=k, replace=False))
    return np.sort(np.concatenate([pri, rng.choice(rest, size=k - len(pri), replace=False)]))


def _density(ax, X: np.ndarray, lo, hi, bins: int = 160, cmap="Blues"):
    """Shade where the states ``X (runs, T+1, 2)`` lie: a light 2-D histogram (log scale) over ``[lo, hi]``."""
    P = X.reshape(-1, 2)
    P = P[np.isfinite(P).all(1)]
    (x0, y0), (x1, y1) = lo[:2], hi[:2]
    nx = max(int(round(bins * (x1 - x0) / max(x1 - x0, y1 - y0))), 1)
    ny = max(int(round(bins * (y1 - y0) / max(x1 - x0, y1 - y0))), 1)
    H, _, _ = np.histogram2d(P[:, 0], P[:, 1], bins=(nx, ny), range=[[x0, x1], [y0, y1]])
    xlim, ylim = ax.get_xlim(), ax.get_ylim()
    img = ax.imshow(np.ma.masked_equal(np.log1p(H.T), 0.0), origin="lower", extent=(x0, x1, y0, y1),
                    cmap=cmap, vmin=0.0, alpha=0.45, interpolation="nearest", zorder=5)
    ax.set_xlim(xlim)
    ax.set_ylim(ylim)
    return img


def _direction_arrows(ax, path: np.ndarray, scale: float, n: int | None = None, color="black") -> list:
    """Arrowheads along ``path (T+1, 2)`` pointing the way it is travelled, about every ``0.12 scale``
    of its length (``n`` of them if given); returns the patches."""
    path = path[np.isfinite(path).all(1)]
    if len(path) < 2:
        return []
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    total = float(s[-1])
    if total <= 1e-12 * max(scale, 1e-300):
        return []
    if n is None:
        n = int(np.clip(round(total / (0.12 * scale)), 3, 40))
    delta = min(0.01 * scale, total / (4 * n))
    at = lambda t: np.array([np.interp(t, s, path[:, 0]), np.interp(t, s, path[:, 1])])  # noqa: E731
    out = []
    for k in range(n):
        t = (k + 0.5) * total / n
        a, b = at(max(t - delta, 0.0)), at(min(t + delta, total))
        if np.linalg.norm(b - a) <= 0.0:
            continue
        arrow = FancyArrowPatch(a, b, arrowstyle="-|>", mutation_scale=11, shrinkA=0, shrinkB=0,
                                facecolor=color, edgecolor="white", linewidth=0.4, zorder=9)
        ax.add_patch(arrow)
        out.append(arrow)
    return out


def _flags(result, names=("tube_exit", "obstacle_entry", "state_constraint_exit")) -> np.ndarray:
    """Runs with any of the flags ``names`` set (missing flags count as false)."""
    n = len(np.asarray(result.trajectories))
    bad = np.zeros(n, bool)
    for flag in names:
        if hasattr(result, flag):
            bad |= np.asarray(getattr(result, flag), bool)
    return bad


def drawn_caption(drawn: int, runs: int, seed, violating: int, density: bool) -> str:
    """The line saying how many of how many runs a figure draws (and what the shading is)."""
    if drawn >= runs:
        text = f"all {runs} runs drawn"
    else:
        text = f"{drawn} of {runs} runs drawn (chosen by seed {seed}"
        text += f", the {violating} violating first)" if violating else ")"
    if density and drawn < runs:
        text += f"; shading: where all {runs} went"
    return text


def plot_trajectories(decomp, result, ax=None, max_runs: int | None = 50, color="tab:blue",
                      show_start_end: bool = True, seed: int | None = None, density: bool = True,
                      arrows: bool = True, state_constraints: dict | None = None):
    """Fig. 7: closed-loop trajectories over the workspace, with the direction of travel.

    Runs with an obstacle entry, a tube exit or a state outside a state constraint are drawn in
    red; initial states are green dots, final states purple dots; black arrowheads along the
    mean of all runs (the runs follow one plan in step) show the direction of travel.

    Parameters
    ----------
    decomp : CellDecomposition
    result : SimulationResult
        (or anything with ``trajectories (runs, T+1, n)`` and optional ``tube_exit``,
        ``obstacle_entry``, ``state_constraint_exit`` flags, ``state_constraints`` and ``seed``)
    max_runs : int or None
        Draw at most this many runs as lines (:func:`select_runs`: chosen from ``seed``,
        violating runs first); ``None``: all.
    seed : int, optional
        Seed of the choice (default: ``result.seed``, else 0).
    density : bool
        When not every run is drawn, shade where all of them went (a light 2-D histogram).
    arrows : bool
        Draw the direction arrows.
    state_constraints : dict, optional
        ``{name: Halfspaces}`` to draw (default: ``result.state_constraints``, the ones checked).

    Returns
    -------
    Axes
        Its title says how many runs of how many are drawn.
    """
    if state_constraints is None:
        state_constraints = getattr(result, "state_constraints", None) or {}
    ax = plot_workspace(decomp, ax, state_constraints=state_constraints)
    X_all = np.asarray(result.trajectories)[:, :, :2]
    n = len(X_all)
    bad_all = _flags(result)
    seed = int(getattr(result, "seed", 0) or 0) if seed is None else int(seed)
    idx = select_runs(n, max_runs, seed, first=bad_all)
    X, bad = X_all[idx], bad_all[idx]
    lo, hi = decomp.bounds()
    if density and len(idx) < n and n:
        _density(ax, X_all, lo, hi)
    if (~bad).any():
        ax.add_collection(LineCollection(list(X[~bad]), colors=color, linewidths=0.6, alpha=0.5, zorder=6))
    if bad.any():
        ax.add_collection(LineCollection(list(X[bad]), colors="red", linewidths=0.8, alpha=0.8,
                                         zorder=7))
    handles = []
    if show_start_end and len(X):
        ax.plot(X[:, 0, 0], X[:, 0, 1], ".", color="tab:green", ms=3, zorder=8)
        ax.plot(X[:, -1, 0], X[:, -1, 1], ".", color="tab:purple", ms=3, zorder=8)
        handles += [Line2D([], [], ls="none", marker=".", color="tab:green", label="start"),
                    Line2D([], [], ls="none", marker=".", color="tab:purple", label="end")]
    finite = np.isfinite(X_all).all(axis=(1, 2))          # a run with a NaN state has no direction to show
    if arrows and finite.any():
        if _direction_arrows(ax, X_all[finite].mean(axis=0), float(np.max(hi[:2] - lo[:2]))):
            handles.append(Line2D([], [], ls="none", marker=">", color="black", label="direction of travel"))
    if bad.any():
        handles.append(Line2D([], [], color="red", label="violating run"))
    if handles:
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=len(handles),
                  fontsize=7, frameon=False)
    caption = drawn_caption(len(idx), n, seed, int(bad_all.sum()), density)
    s = result.summary() if hasattr(result, "summary") else None
    if s:
        ax.set_title(f"{s['runs']} runs ({s['mode']}): {s['obstacle_entries']} obstacle entries, "
                     f"{s['tube_exits']} tube exits{outside_text(s)}\n{caption}", fontsize=9)
    else:
        ax.set_title(caption, fontsize=9)
    return ax


def discrete_colours(values, cmap="plasma") -> dict:
    """One colour per distinct value of ``values`` (sorted), from ``cmap`` (its pale end left out)."""
    vals = sorted(set(values))
    cm = plt.get_cmap(cmap)
    pos = np.linspace(0.0, 0.85, len(vals)) if len(vals) > 1 else np.zeros(1)
    return {v: cm(float(p)) for v, p in zip(vals, pos)}


def plot_transition_graph(ts, ax=None, cmap="plasma", workspace: bool = True):
    """The transition system: nodes at cell centroids, arrows coloured by ``L``.

    ``L`` takes few values, so its colours are discrete: one colour per value of ``L``,
    named in a legend (with the number of edges of each) beside the axes.

    Returns
    -------
    Axes
    """
    ax = _ax(ax)
    d = ts.decomposition
    if workspace:
        plot_workspace(d, ax, labels=False, state_constraints=system_constraints(ts))
    C = np.array([P.centroid[:2] for P in d.cells])
    Ls = [int(e.L) for e in ts.edges]
    colour = discrete_colours(Ls, cmap)
    pairs = {(e.src, e.dst) for e in ts.edges}
    for e in ts.edges:
        a, b = C[e.src], C[e.dst]
        rad = 0.15 if (e.dst, e.src) in pairs else 0.0
        ax.add_patch(FancyArrowPatch(a, b, arrowstyle="-|>", mutation_scale=7,
                                     connectionstyle=f"arc3,rad={rad}", color=colour[int(e.L)],
                                     linewidth=0.6, alpha=0.8, shrinkA=3, shrinkB=3, zorder=6))
    ax.scatter(C[:, 0], C[:, 1], s=14, color="k", zorder=7)
    for i, c in enumerate(C):
        if d.labels[i] is not None:
            ax.annotate(str(d.labels[i]), c, xytext=(3, 3), textcoords="offset points",
                        fontsize=8, fontweight="bold", zorder=8)
    if colour:
        counts = {v: Ls.count(v) for v in colour}
        handles = [Line2D([], [], color=c, lw=2, label=f"{v} ({counts[v]})") for v, c in colour.items()]
        ax.legend(handles=handles, title="L (edges)", loc="upper left", bbox_to_anchor=(1.02, 1.0),
                  borderaxespad=0.0, fontsize=7, title_fontsize=8, frameon=False,
                  ncol=math.ceil(len(handles) / 20))
    lo, hi = d.bounds()
    ax.set_xlim(lo[0] - 0.1, hi[0] + 0.1)
    ax.set_ylim(lo[1] - 0.1, hi[1] + 0.1)
    ax.set_aspect("equal")
    ax.set_title(f"{ts.n_cells} cells, {ts.n_edges} transitions", fontsize=9)
    return ax


def save_figure(fig, directory, stem: str, dpi: int = 150) -> tuple[Path, Path]:
    """Write ``directory/<stem>.png`` and ``directory/<stem>.pdf``; returns both paths.

    Saved inside :func:`figure_style`: the PDF embeds its fonts as TrueType (Type 42).

    Parameters
    ----------
    fig : Figure or Axes
        An ``Axes`` stands for its figure.
    directory : path
        Created if missing.
    stem : str
    dpi : int
        Resolution of the PNG (the PDF is vector graphics).

    Returns
    -------
    (Path, Path)
        The PNG and the PDF.
    """
    fig = getattr(fig, "figure", fig) if not hasattr(fig, "savefig") else fig
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    png, pdf = directory / f"{stem}.png", directory / f"{stem}.pdf"
    with figure_style():
        fig.savefig(png, dpi=dpi, bbox_inches="tight")
        fig.savefig(pdf, bbox_inches="tight")
    return png, pdf
