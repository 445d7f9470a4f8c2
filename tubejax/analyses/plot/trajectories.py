"""Fig. 7: closed-loop trajectories over the workspace, and which runs a figure draws.

:func:`plot_trajectories` draws ``max_runs`` runs (:func:`select_runs`: from the seed, violating runs
first), shades where all of them went and says in its title how many of how many it drew
(:func:`drawn_caption`). The figures only read the results.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.lines import Line2D
from matplotlib.patches import FancyArrowPatch

from .figures import plot_workspace
from .constraint_layer import outside_text
from .style import PALETTE, paper_style

__all__ = ["RunsStyle", "plot_trajectories", "select_runs", "drawn_caption", "runs_title", "RUN_COLOURS"]

#: The colours of the runs' figures (Figs. 7 and 8), from the colour-blind-safe palette.
RUN_COLOURS = {"run": PALETTE["blue"], "violating": PALETTE["vermillion"], "start": PALETTE["green"],
               "end": PALETTE["purple"]}



def select_runs(n_runs: int, max_runs: int | None, seed: int = 0, first=None) -> np.ndarray:
    """The sorted indices of the runs a figure draws: at most ``max_runs`` (``None``: all) of ``n_runs``, chosen
    by :func:`numpy.random.default_rng` of ``seed``; the runs ``first (n_runs,)`` (violating ones) before any other."""
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


def _density(ax, X: np.ndarray, lo, hi, bins: int = 64, cmap="Blues"):
    """Shade where the states ``X (runs, T+1, 2)`` lie: a light log-scale 2-D histogram over ``[lo, hi]``, its
    bins (``bins`` along the longer side) wider than a line, so runs that keep close together show a band."""
    P = X.reshape(-1, 2)
    P = P[np.isfinite(P).all(1)]
    (x0, y0), (x1, y1) = lo[:2], hi[:2]
    nx = max(int(round(bins * (x1 - x0) / max(x1 - x0, y1 - y0))), 1)
    ny = max(int(round(bins * (y1 - y0) / max(x1 - x0, y1 - y0))), 1)
    H, _, _ = np.histogram2d(P[:, 0], P[:, 1], bins=(nx, ny), range=[[x0, x1], [y0, y1]])
    xlim, ylim = ax.get_xlim(), ax.get_ylim()
    img = ax.imshow(np.ma.masked_equal(np.log1p(H.T), 0.0), origin="lower", extent=(x0, x1, y0, y1),
                    cmap=cmap, vmin=-0.5, alpha=0.5, interpolation="nearest", zorder=5)
    ax.set(xlim=xlim, ylim=ylim)
    return img


def _run_lines(color) -> tuple[dict, dict]:
    """How the runs' lines are drawn: ``(violating nothing, in color; violating, over them)``."""
    return (dict(color=color, linewidth=0.6, alpha=0.5, zorder=6),
            dict(color=RUN_COLOURS["violating"], linewidth=0.8, alpha=0.8, zorder=7))


def _draw_runs(ax, X_all: np.ndarray, chosen: tuple, bounds, density: bool, color=RUN_COLOURS["run"],
               ends=("start", "end")) -> tuple:
    """The runs of Figs. 7 and 8: shading where all runs ``X_all (runs, T+1, 2)`` went when not all are drawn
    (``density``, over ``bounds = (lo, hi)``), the runs ``chosen = (bad_all, idx, seed)`` (:func:`_chosen`) as
    lines (:func:`_run_lines`), dots at their ``ends``. Returns ``(X (drawn, T+1, 2), bad (drawn,), caption)``."""
    bad_all, idx, seed = chosen
    X, bad = X_all[idx], bad_all[idx]
    if density and len(idx) < len(X_all):
        _density(ax, X_all, *bounds)
    for runs, style in zip((~bad, bad), _run_lines(color)):
        if runs.any():
            ax.add_collection(LineCollection(list(X[runs]), **style))
    for end, k in (("start", 0), ("end", -1)):
        if end in ends and len(X):
            ax.plot(X[:, k, 0], X[:, k, 1], ".", color=RUN_COLOURS[end], ms=3, zorder=8)
    return X, bad, drawn_caption(len(idx), len(X_all), seed, int(bad_all.sum()), density)


def _direction_arrows(ax, path: np.ndarray, scale: float, least: int = 3, color="black") -> list:
    """Arrowheads along ``path (T+1, 2)`` the way it is travelled, about every ``0.12 scale`` (``least`` to 40 of them),
    a little right of it (``0.012 scale``: a corridor used both ways shows both directions); returns them."""
    path = path[np.isfinite(path).all(1)]
    if len(path) < 2:
        return []
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    total = float(s[-1])
    if total <= 1e-12 * max(scale, 1e-300):
        return []
    n = int(np.clip(round(total / (0.12 * scale)), least, 40))
    delta = min(0.01 * scale, total / (4 * n))
    at = lambda t: np.array([np.interp(t, s, path[:, 0]), np.interp(t, s, path[:, 1])])  # noqa: E731
    out = []
    for k in range(n):
        t = (k + 0.5) * total / n
        a, b = at(max(t - delta, 0.0)), at(min(t + delta, total))
        if np.linalg.norm(b - a) <= 0.0:
            continue
        d = (b - a) / np.linalg.norm(b - a)
        right = 0.012 * scale * np.array([d[1], -d[0]])
        a, b = a + right, b + right
        arrow = FancyArrowPatch(a, b, arrowstyle="-|>", mutation_scale=11, shrinkA=0, shrinkB=0,
                                facecolor=color, edgecolor="white", linewidth=0.4, zorder=9)
        ax.add_patch(arrow)
        out.append(arrow)
    return out


def _run_handles(dots: bool, arrows: bool, violating: bool) -> list:
    """The legend entries of a runs' figure: start and end dots, the direction arrows, a violating run."""
    out = [Line2D([], [], ls="none", marker=".", color=RUN_COLOURS[k], label=k) for k in ("start", "end") if dots]
    if arrows:
        out.append(Line2D([], [], ls="none", marker=">", color="black", label="direction of travel"))
    if violating:
        out.append(Line2D([], [], color=RUN_COLOURS["violating"], label="violating run"))
    return out


def _flags(result, names=("tube_exit", "obstacle_entry", "state_constraint_exit")) -> np.ndarray:
    """Runs with any of the flags ``names`` set (missing flags count as false)."""
    n = len(np.asarray(result.trajectories))
    bad = np.zeros(n, bool)
    for flag in names:
        if hasattr(result, flag):
            bad |= np.asarray(getattr(result, flag), bool)
    return bad


def _chosen(result, max_runs: int | None, seed=None, bad=None) -> tuple:
    """``(bad (runs,), idx, seed)``: the violating runs (``bad`` or :func:`_flags`) and those a figure draws
    (:func:`select_runs` from ``seed``, default ``result.seed``, else 0)."""
    bad = _flags(result) if bad is None else np.asarray(bad, bool) | _flags(result)
    seed = int(getattr(result, "seed", 0) or 0) if seed is None else int(seed)
    return bad, select_runs(len(bad), max_runs, seed, first=bad), seed


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


def runs_title(result, caption: str) -> str:
    """The title of a runs' figure: in the ``paper`` style one line saying what is drawn; in the
    ``draft`` style the run log (``result.summary()``, if it has one) and ``caption`` (how many runs are drawn)."""
    s = result.summary() if hasattr(result, "summary") else None
    if paper_style():
        return f"{s['runs']} closed-loop runs ({s['mode']} disturbances)" if s else caption.split(";")[0]
    if s:
        return (f"{s['runs']} runs ({s['mode']}): {s['obstacle_entries']} obstacle entries, "
                f"{s['tube_exits']} tube exits{outside_text(s)}\n{caption}")
    return caption


@dataclass(frozen=True)
class RunsStyle:
    """Which closed-loop runs a trajectory figure draws, and how (:func:`plot_trajectories`).

    Attributes
    ----------
    max_runs : int or None
        At most this many runs as lines (:func:`select_runs`); ``None``: all.
    seed : int, optional
        Seed of the choice (default: ``result.seed``, else 0).
    color
        Colour of the runs that violate nothing.
    show_start_end, density, arrows : bool
        Dots at the initial and final states; shade where all runs went when not all are drawn; direction arrows.
    """

    max_runs: int | None = 50
    seed: int | None = None
    color: object = RUN_COLOURS["run"]
    show_start_end: bool = True
    density: bool = True
    arrows: bool = True


def plot_trajectories(decomp, result, ax=None, runs: RunsStyle = RunsStyle(), state_constraints: dict | None = None):
    """Fig. 7: closed-loop trajectories over the workspace, with the direction of travel.

    Violating runs (an obstacle entry, a tube exit, a state outside a constraint) in vermillion, initial
    states green, final states purple; black arrowheads along the mean run show the direction of travel.

    Parameters
    ----------
    decomp : CellDecomposition
    result : SimulationResult
        Or anything with ``trajectories (runs, T+1, n)`` and optional ``tube_exit``, ``obstacle_entry``,
        ``state_constraint_exit`` flags, ``state_constraints`` and ``seed``.
    runs : RunsStyle
    state_constraints : dict, optional
        ``{name: Halfspaces}`` to draw (default: ``result.state_constraints``, the ones checked).

    Returns
    -------
    Axes
        Its title says how many runs of how many are drawn.
    """
    if state_constraints is None:
        state_constraints = getattr(result, "state_constraints", None) or {}
    ax = plot_workspace(decomp, ax, state_constraints=state_constraints, labels_aside=True)
    X_all = np.asarray(result.trajectories)[:, :, :2]
    lo, hi = decomp.bounds()
    X, bad, caption = _draw_runs(ax, X_all, _chosen(result, runs.max_runs, runs.seed), (lo, hi), runs.density,
                                 runs.color, ("start", "end") if runs.show_start_end else ())
    dots = runs.show_start_end and len(X)
    finite = np.isfinite(X_all).all(axis=(1, 2))          # a run with a NaN state has no direction to show
    arrows = runs.arrows and finite.any() and _direction_arrows(ax, X_all[finite].mean(axis=0),
                                                                float(np.max(hi[:2] - lo[:2])))
    handles = _run_handles(dots, arrows, bad.any())
    if handles:
        ax.legend(handles=handles, loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=len(handles),
                  fontsize=7, frameon=False)
    ax.set_title(runs_title(result, caption), fontsize=None if paper_style() else 9)
    return ax
