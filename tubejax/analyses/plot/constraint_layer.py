"""The system's state constraints in the 2-D figures: outside hatched grey, boundary dashed, ``outside <name>``.

A constraint may be unbounded, so it is clipped to (a box around) the axes' view. For ``n > 2`` only the
rows of ``H`` in the first two coordinates alone are drawn (the drawn set contains the projection);
a constraint without such rows, or ``n < 2``, draws nothing.
"""

from __future__ import annotations

import matplotlib
import numpy as np
import shapely
from matplotlib.patches import PathPatch, Polygon as MplPolygon
from matplotlib.path import Path

from ...reachability.exact2d import clip_halfplanes

__all__ = ["plot_state_constraints", "system_constraints", "outside_text"]


def system_constraints(ts) -> dict:
    """``ts.system.state_constraints`` (``{}`` for an object without a system or constraints)."""
    return dict(getattr(getattr(ts, "system", None), "state_constraints", None) or {})


def _path(geom) -> Path:
    """A (multi)polygon with its holes as one matplotlib ``Path`` (holes wound the other way)."""
    verts, codes = [], []
    for g in getattr(geom, "geoms", [geom]):
        if not isinstance(g, shapely.Polygon) or g.is_empty:
            continue
        g = shapely.geometry.polygon.orient(g, 1.0)
        for ring in [g.exterior, *g.interiors]:
            xy = np.asarray(ring.coords)
            verts.append(xy)
            codes += [Path.MOVETO] + [Path.LINETO] * (len(xy) - 2) + [Path.CLOSEPOLY]
    return Path(np.concatenate(verts) if verts else np.zeros((0, 2)), codes or None)


def plot_state_constraints(ax, constraints: dict, color="0.35"):
    """Hatch the part of the view outside each state constraint and dash its boundary.

    Parameters
    ----------
    ax : Axes
        Drawn within its current limits, which it keeps (the sets are clipped to three times the view).
    constraints : dict
        ``{name: Halfspaces}`` in ``R^n`` (e.g. ``system.state_constraints``; may be empty).
    color : colour
        Of the hatching, the boundary and the label.

    Returns
    -------
    list of str
        The names drawn.
    """
    xlim, ylim = ax.get_xlim(), ax.get_ylim()
    (x0, x1), (y0, y1) = sorted(xlim), sorted(ylim)
    dx, dy = max(x1 - x0, 1e-12), max(y1 - y0, 1e-12)
    view = np.array([[x0 - dx, y0 - dy], [x1 + dx, y0 - dy], [x1 + dx, y1 + dy], [x0 - dx, y1 + dy]])
    rgb = matplotlib.colors.to_rgb(color)
    drawn = []
    for name, S in constraints.items():
        H, h = np.asarray(S.H, float), np.asarray(S.h, float)
        if H.shape[1] < 2:
            continue
        rows = ~np.any(H[:, 2:] != 0, axis=1)                # rows in (x_1, x_2) alone
        if not rows.any():
            continue
        inside = clip_halfplanes(view, H[rows, :2], h[rows])
        outside = shapely.Polygon(view)
        if len(inside) >= 3:
            outside = outside.difference(shapely.Polygon(inside))
        visible = outside.intersection(shapely.box(x0, y0, x1, y1))
        if visible.is_empty or visible.area <= 1e-12 * dx * dy:
            continue
        ax.add_patch(PathPatch(_path(outside), facecolor=(*rgb, 0.12), edgecolor=(*rgb, 0.6), hatch="\\\\",
                               linewidth=0.0, zorder=2.5))
        if len(inside) >= 3:
            ax.add_patch(MplPolygon(inside, closed=True, facecolor="none", edgecolor=color, linestyle="--",
                                    linewidth=1.0, zorder=2.6))
        p = max(getattr(visible, "geoms", [visible]), key=lambda g: g.area).representative_point()
        ax.text(p.x, p.y, f"outside {name}", ha="center", va="center", fontsize=8, color=color, zorder=9,
                bbox=dict(boxstyle="round,pad=0.15", fc="white", ec="none", alpha=0.7))
        drawn.append(name)
    ax.set(xlim=xlim, ylim=ylim)
    return drawn


def outside_text(s: dict) -> str:
    """``", 3 states outside X"`` per state constraint of a summary (``""`` when it has none)."""
    return "".join(f", {c} states outside {k}" for k, c in (s.get("outside_state_constraints") or {}).items())


