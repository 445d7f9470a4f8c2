"""Overlap areas of convex polygons with rectilinear obstacles, vectorised (2-D).

The obstacle case (:mod:`tubejax.model.workspace.obstacle_index`) needs ``area(P_ij ∩ O)`` for many
hulls. A grid map's walls split into rectangles with disjoint interiors (:func:`rectangles_of`), and
a convex polygon's area inside a rectangle is one Sutherland-Hodgman clip (:func:`convex_box_areas`),
for all (hull, rectangle) pairs at once; the sum is the overlap with the union.
"""

from __future__ import annotations

import numpy as np
import shapely

__all__ = ["rectangles_of", "convex_box_areas", "polygon_vertices"]


def rectangles_of(union) -> np.ndarray | None:
    """Axis-aligned rectangles with disjoint interiors whose union is ``union``, ``(R, 4)`` rows
    ``(x0, y0, x1, y1)``; ``None`` unless ``union`` is rectilinear (every part of it between two
    consecutive vertex abscissae is a rectangle)."""
    coords = shapely.get_coordinates(union)
    if coords.size == 0:
        return None
    xs = np.unique(coords[:, 0])
    y0, y1 = float(coords[:, 1].min()), float(coords[:, 1].max())
    if len(xs) < 2:
        return None
    slabs = shapely.box(xs[:-1], y0, xs[1:], y1)
    parts = shapely.get_parts(shapely.intersection(union, slabs))
    parts = parts[shapely.get_type_id(parts) == 3]
    parts = parts[shapely.area(parts) > 0]
    if not len(parts) or np.any(shapely.get_num_interior_rings(parts) > 0):
        return None
    b = shapely.bounds(parts)
    box_area = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    if not np.all(np.abs(shapely.area(parts) - box_area) <= 1e-12 * box_area):
        return None                                     # some part is no rectangle
    if not np.isclose(box_area.sum(), shapely.area(union), rtol=1e-12, atol=0.0):
        return None
    return b


def polygon_vertices(geoms) -> tuple[np.ndarray, np.ndarray]:
    """The exterior vertices of shapely polygons (without the closing point), padded:
    ``V (K, M, 2)`` and the counts ``(K,)``."""
    rings = shapely.get_exterior_ring(geoms)
    coords, which = shapely.get_coordinates(rings, return_index=True)
    counts = np.bincount(which, minlength=len(geoms))
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    n = np.maximum(counts - 1, 0)
    M = int(n.max()) if len(n) else 0
    idx = starts[:, None] + np.minimum(np.arange(M)[None, :], np.maximum(n - 1, 0)[:, None])
    return coords[idx] if len(coords) else np.zeros((len(geoms), M, 2)), n


def _clip(V, cnt, axis: int, bound, sign: float):
    """Sutherland-Hodgman: the part of each polygon with ``sign * (x[axis] - bound) >= 0``."""
    K, M, _ = V.shape
    i = np.arange(M)[None, :]
    live = i < cnt[:, None]
    nxt = np.where(i + 1 < cnt[:, None], i + 1, 0)
    W = np.take_along_axis(V, nxt[:, :, None], axis=1)                  # the next vertex
    s = sign * (V[:, :, axis] - bound[:, None])
    t_ = sign * (W[:, :, axis] - bound[:, None])
    a_in, b_in = s >= 0, t_ >= 0
    with np.errstate(divide="ignore", invalid="ignore"):
        f = np.where(a_in != b_in, s / (s - t_), 0.0)
    X = V + f[:, :, None] * (W - V)                                      # where the edge crosses
    out = np.stack([X, W], axis=2).reshape(K, 2 * M, 2)                  # per edge: crossing, next
    keep = np.stack([live & (a_in != b_in), live & b_in], axis=2).reshape(K, 2 * M)
    order = np.argsort(~keep, axis=1, kind="stable")                     # kept ones first, in order
    n = keep.sum(axis=1)
    M2 = max(int(n.max()), 1)
    return np.take_along_axis(out, order[:, :M2, None], axis=1), n


def convex_box_areas(V, cnt, lo, hi) -> np.ndarray:
    """Areas of ``polygon_k ∩ [lo_k, hi_k]``, shape ``(K,)``.

    Parameters
    ----------
    V : ndarray, shape (K, M, 2)     convex polygons' vertices in order (either orientation)
    cnt : ndarray of int, shape (K,) their vertex counts
    lo, hi : ndarray, shape (K, 2)   the boxes
    """
    V = np.asarray(V, float)
    cnt = np.asarray(cnt, int)
    if len(V) == 0:
        return np.zeros(0)
    for axis, bound, sign in ((0, lo[:, 0], 1.0), (0, hi[:, 0], -1.0), (1, lo[:, 1], 1.0), (1, hi[:, 1], -1.0)):
        V, cnt = _clip(V, cnt, axis, np.asarray(bound, float), sign)
    M = V.shape[1]
    i = np.arange(M)[None, :]
    live = i < cnt[:, None]
    nxt = np.where(i + 1 < cnt[:, None], i + 1, 0)
    W = np.take_along_axis(V, nxt[:, :, None], axis=1)
    cross = V[:, :, 0] * W[:, :, 1] - W[:, :, 0] * V[:, :, 1]
    return 0.5 * np.abs(np.sum(np.where(live, cross, 0.0), axis=1))
