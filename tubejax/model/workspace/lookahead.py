"""Maps lifted to double-integrator state spaces: velocity divisions per axis
(docs/math/drone.md#the-state-space-velocity-divisions).

A system of ``d`` double integrators in look-ahead coordinates moves over a ``d``-D map of boxes;
:func:`lift_lookahead` makes its ``2d``-D cells, each a map cell times one look-ahead slab per axis
(a 2-D map's rectilinear walls split into rectangles first). The lifted decomposition keeps its
position view (:func:`position_view`) for figures drawn over the map.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass

import numpy as np
import shapely

from ...errors import InputError
from ..geometry import Polytope
from .decomposition import CellDecomposition
from .rectilinear import rectangles_of

__all__ = ["VelocityDivisionsError", "PositionView", "POSITION_VIEW", "MAX_LIFTED_CELLS", "lift_lookahead",
           "position_view", "velocity_division_count"]

#: Key of ``CellDecomposition._cache`` holding the :class:`PositionView` of a lifted decomposition.
POSITION_VIEW = "position_view"
#: Most cells a lift may make (map cells x velocity divisions).
MAX_LIFTED_CELLS = 10_000_000


class VelocityDivisionsError(InputError):
    """Bad ``workspace.velocity_divisions`` or a map that cannot be lifted; the message names the value."""


@dataclass(frozen=True)
class PositionView:
    """How a lifted decomposition's cells sit over its map.

    Attributes
    ----------
    base : CellDecomposition
        The map (``d``-D).
    axes : tuple of int
        The state coordinates that are positions, ``(0, 2, .., 2d - 2)``.
    base_cell : ndarray of int, shape (N,)
        The map cell under each lifted cell.
    """

    base: CellDecomposition
    axes: tuple
    base_cell: np.ndarray


def velocity_division_count(value, d: int) -> np.ndarray:
    """``workspace.velocity_divisions`` as ``d`` positive integers (an int applies to every axis).

    Raises
    ------
    VelocityDivisionsError
        Not a positive integer, nor a list of ``d`` of them.
    """
    items = [value] * d if isinstance(value, numbers.Integral) and not isinstance(value, bool) else value
    expected = f"a positive integer or a list of {d} (one per axis of the {d}-D map)"
    if not isinstance(items, (list, tuple, np.ndarray)) or len(items) != d:
        raise VelocityDivisionsError(f"workspace.velocity_divisions: expected {expected}, got {value!r}")
    for v in items:
        if isinstance(v, bool) or not isinstance(v, numbers.Integral) or v < 1:
            raise VelocityDivisionsError(f"workspace.velocity_divisions: expected {expected}, got {value!r}")
    return np.asarray(items, dtype=int)


def _obstacle_boxes(obstacles, d: int, name: str) -> tuple[np.ndarray, np.ndarray]:
    """The obstacles as boxes ``(lo, hi)``, shape ``(k, d)`` each: box polytopes as they are, a 2-D
    grid map's rectilinear polygons split into rectangles with disjoint interiors."""
    boxes, geoms = [], []
    for P in obstacles:
        (boxes if isinstance(P, Polytope) else geoms).append(P)
    lo, hi = _boxes(boxes, d, "obstacle", name)
    if geoms:
        rects = rectangles_of(shapely.union_all(geoms)) if d == 2 else None
        if rects is None:
            raise VelocityDivisionsError(f"{name}: workspace.velocity_divisions needs a map of axis-aligned boxes "
                                         "(a grid or voxel map, a box grid); an obstacle is not rectilinear")
        lo, hi = np.vstack([lo, rects[:, :2]]), np.vstack([hi, rects[:, 2:]])
    return lo, hi


def _boxes(polys, d: int, what: str, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Bounding boxes ``(lo, hi)`` of ``polys``, shape ``(k, d)`` each; refused unless each is a box."""
    lo, hi = [], []
    for k, P in enumerate(polys):
        if not (isinstance(P, Polytope) and P.is_box):
            raise VelocityDivisionsError(f"{name}: workspace.velocity_divisions needs a map of axis-aligned boxes "
                                         f"(a grid or voxel map, a box grid); {what} {k} is not a box")
        a, b = P.bounding_box()
        lo.append(a)
        hi.append(b)
    return np.asarray(lo, float).reshape(-1, d), np.asarray(hi, float).reshape(-1, d)


def _interleave(p: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``(..., d)`` positions and ``(..., d)`` look-aheads as ``(..., 2d)`` states ``(p_1, s_1, ..)``."""
    out = np.empty(p.shape[:-1] + (2 * p.shape[-1],), dtype=float)
    out[..., 0::2], out[..., 1::2] = p, s
    return out


def lift_lookahead(base: CellDecomposition, velocity_divisions) -> CellDecomposition:
    """The ``2d``-D decomposition of ``base`` (``d``-D boxes) with velocity divisions (module doc).

    Parameters
    ----------
    base : CellDecomposition
        The map: cells and obstacles axis-aligned boxes in ``R^d``.
    velocity_divisions : int or sequence of int, shape (d,)
        Slabs of the look-ahead range per axis.

    Returns
    -------
    CellDecomposition
        ``N = base.n_cells * prod(velocity_divisions)`` box cells in ``R^{2d}``, its
        :class:`PositionView` in ``_cache[POSITION_VIEW]``.

    Raises
    ------
    VelocityDivisionsError
        Bad ``velocity_divisions``, a map that is not made of boxes, or more than
        :data:`MAX_LIFTED_CELLS` cells.
    """
    d = base.dim
    div = velocity_division_count(velocity_divisions, d)
    per_cell = int(np.prod(div))
    total = base.n_cells * per_cell
    if total > MAX_LIFTED_CELLS:
        raise VelocityDivisionsError(f"workspace.velocity_divisions: {base.n_cells:,} map cells x "
                                     f"{' x '.join(map(str, div))} divisions = {total:,} cells, more than the limit "
                                     f"of {MAX_LIFTED_CELLS:,}")
    c_lo, c_hi = _boxes(base.cells, d, "cell", base.name)
    o_lo, o_hi = _obstacle_boxes(base.obstacles, d, base.name)
    if base.domain is not None:
        lo, hi = base.domain.bounding_box()
    else:
        lo, hi = c_lo.min(axis=0), c_hi.max(axis=0)
        if len(o_lo):
            lo, hi = np.minimum(lo, o_lo.min(axis=0)), np.maximum(hi, o_hi.max(axis=0))
    edges = [np.linspace(lo[k], hi[k], div[k] + 1) for k in range(d)]
    sub = np.indices(tuple(div)).reshape(d, -1).T                          # (per_cell, d), C order
    s_lo = np.stack([edges[k][sub[:, k]] for k in range(d)], axis=1)       # (per_cell, d)
    s_hi = np.stack([edges[k][sub[:, k] + 1] for k in range(d)], axis=1)
    base_cell = np.repeat(np.arange(base.n_cells), per_cell)               # (N,)
    x_lo = _interleave(c_lo[base_cell], np.tile(s_lo, (base.n_cells, 1)))  # (N, 2d)
    x_hi = _interleave(c_hi[base_cell], np.tile(s_hi, (base.n_cells, 1)))
    cells = _boxes_of(x_lo, x_hi)
    obstacles = tuple(Polytope.box(_interleave(a, lo), _interleave(b, hi)) for a, b in zip(o_lo, o_hi))
    base_grid = (np.arange(base.n_cells)[:, None] if base.grid is None else np.asarray(base.grid, int))
    grid = np.hstack([base_grid[base_cell], np.tile(sub, (base.n_cells, 1))])
    labels = tuple(base.labels[b] for b in base_cell)
    out = CellDecomposition(cells, labels, obstacles, grid,
                            f"{base.name} x velocity divisions {list(map(int, div))}",
                            domain=Polytope.box(_interleave(lo, lo), _interleave(hi, hi)))
    out._cache[POSITION_VIEW] = PositionView(base, tuple(range(0, 2 * d, 2)), base_cell)
    for x in (x_lo, x_hi):
        x.setflags(write=False)
    out._cache["cell_boxes"] = (x_lo, x_hi)          # what CellDecomposition.cell_boxes() computes
    return out


def _boxes_of(lo: np.ndarray, hi: np.ndarray) -> tuple:
    """The boxes ``[lo[k], hi[k]]`` (``(N, n)`` each) as :class:`Polytope` s, equal to
    ``Polytope.box(lo[k], hi[k])``: vertices in the canonical order (for ``n != 2``, binary counting,
    axis ``k`` the ``k``-th bit), built at once; one read-only ``H`` shared by all."""
    n = lo.shape[1]
    if n == 2 or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))
                      and np.all(np.round(lo, 12) < np.round(hi, 12))):
        return tuple(Polytope.box(a, b) for a, b in zip(lo, hi))
    bit = (np.arange(2 ** n)[:, None] >> np.arange(n)[None, :]) & 1 == 1          # (2^n, n)
    V = np.where(bit[None], hi[:, None, :], lo[:, None, :])                        # (N, 2^n, n)
    H = np.vstack([-np.eye(n), np.eye(n)])
    H.setflags(write=False)
    h = np.concatenate([-lo, hi], axis=1)                                          # (N, 2n)
    return tuple(Polytope(v, H, b) for v, b in zip(V, h))


def position_view(decomp: CellDecomposition) -> PositionView | None:
    """The :class:`PositionView` of a lifted decomposition (:func:`lift_lookahead`), else ``None``."""
    return decomp._cache.get(POSITION_VIEW)
