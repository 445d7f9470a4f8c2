"""Pair hulls ``P_ij = co(P_i u P_j)`` of many pairs at once (docs/math/problem-data.md).

* 2-D: one vectorised shapely ``convex_hull`` over ``multipoints(..., indices=)``, then the
  H-representations of all hulls with the same vertex count in one NumPy pass
  (:func:`convex_polygons`, bit-identical to :meth:`Polytope.from_convex_polygon`).
* n-D: qhull, once per *shape* of a pair: two pairs whose stacked vertices differ by a
  translation (up to ``1e-9`` of the cell size) share which points are extreme and the facet
  normals; the facet offsets ``h`` are recomputed from each pair's own vertices (the support
  value, so the polytope is exactly ``{x : H x <= max_v H v}`` over its own points).

Points are always stacked as ``P_min(i,j)`` then ``P_max(i,j)``, so ``P_ij`` and ``P_ji`` are the
same polytope.
"""

from __future__ import annotations

import numpy as np
import shapely
from scipy.spatial import ConvexHull

from ..geometry import Polytope, convex_hull_of
from ..geometry.polytope import _unique_rows, canonical_vertex_order

__all__ = ["convex_polygons", "padded_vertices", "pair_hull_geoms", "pair_hull_polytopes", "pair_hull_hreps"]

#: Relative rounding of the translation-invariant shape key of an n-D pair (a fraction of the
#: pair's extent): pairs closer than this share qhull's combinatorial answer.
_SHAPE_KEY_DECIMALS = 9


def padded_vertices(cells) -> tuple[np.ndarray, np.ndarray]:
    """Cell vertices padded with zeros to one count: ``V`` of shape ``(N, nv_max, n)`` and the
    vertex counts, shape ``(N,)``."""
    counts = np.array([c.n_vertices for c in cells])
    V = np.zeros((len(cells), int(counts.max()), cells[0].dim))
    for k, c in enumerate(cells):
        V[k, :counts[k]] = c.vertices
    return V, counts


def _stacked(cells, src, dst, padded=None):
    """Vertices of ``P_min`` then ``P_max`` for each pair, as ``(coords (sum, n), counts (K,))``."""
    a, b = np.minimum(src, dst), np.maximum(src, dst)
    V, cnt = padded_vertices(cells) if padded is None else padded
    nv = V.shape[1]
    stacked = np.concatenate([V[a], V[b]], axis=1)                      # (K, 2 nv, n)
    if np.all(cnt == nv):
        return stacked.reshape(-1, V.shape[2]), np.full(len(a), 2 * nv)
    mask = np.concatenate([np.arange(nv)[None, :] < cnt[a][:, None],
                           np.arange(nv)[None, :] < cnt[b][:, None]], axis=1)
    return stacked[mask], cnt[a] + cnt[b]


def pair_hull_geoms(cells, src, dst, padded=None) -> np.ndarray:
    """2-D: the shapely polygons of ``P_ij`` for pairs ``(src[k], dst[k])``, shape ``(K,)``.

    ``padded``: :func:`padded_vertices` of ``cells``, if the caller keeps it.
    """
    src, dst = np.asarray(src, int), np.asarray(dst, int)
    if len(src) == 0:
        return np.empty(0, dtype=object)
    coords, counts = _stacked(cells, src, dst, padded)
    idx = np.repeat(np.arange(len(src)), counts)
    return shapely.convex_hull(shapely.multipoints(coords, indices=idx))


def convex_polygons(geoms) -> list:
    """:class:`Polytope` of each convex shapely polygon (no collinear points), vectorised.

    Equal, bit for bit, to ``Polytope.from_convex_polygon(exterior ring)`` of each one.

    Parameters
    ----------
    geoms : ndarray of shapely.Polygon, shape (K,)

    Returns
    -------
    list of Polytope, length K
    """
    rings = shapely.get_exterior_ring(geoms)
    coords, which = shapely.get_coordinates(rings, return_index=True)
    counts = np.bincount(which, minlength=len(geoms))
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    out = [None] * len(geoms)
    for c in np.unique(counts):
        ks = np.flatnonzero(counts == c)
        if c - 1 < 3:
            raise ValueError(f"a pair hull is degenerate ({c} ring points)")
        V = coords[starts[ks][:, None] + np.arange(c - 1)[None, :]]          # (g, c-1, 2), no closing point
        area2 = np.sum(V[:, :, 0] * np.roll(V[:, :, 1], -1, axis=1)
                       - np.roll(V[:, :, 0], -1, axis=1) * V[:, :, 1], axis=1)
        V = np.where((area2 < 0)[:, None, None], V[:, ::-1], V)
        start = np.lexsort((np.round(V[:, :, 0], 12), np.round(V[:, :, 1], 12)), axis=-1)[:, 0]
        ext = np.take_along_axis(V, ((np.arange(c - 1)[None, :] + start[:, None]) % (c - 1))[:, :, None],
                                 axis=1)
        e = np.roll(ext, -1, axis=1) - ext
        H = np.stack([e[:, :, 1], -e[:, :, 0]], axis=2)
        H /= np.linalg.norm(H, axis=2, keepdims=True)
        h = np.einsum("bij,bij->bi", H, ext)
        for r, k in enumerate(ks):
            out[k] = Polytope(ext[r], H[r], h[r])
    return out


def _hull_shape(points: np.ndarray, cache: dict) -> tuple:
    """qhull's answer for a pair's stacked points ``(n_p, n)``, once per shape: ``(vertex
    indices, unique facet normals (f, n))``."""
    rel = points - points[0]
    scale = max(float(np.max(np.abs(rel))), 1e-300)
    key = (points.shape, np.round(rel / scale, _SHAPE_KEY_DECIMALS).tobytes())
    hit = cache.get(key)
    if hit is None:
        n = points.shape[1]
        hull = ConvexHull(points)
        H, _ = _unique_rows(hull.equations[:, :n], -hull.equations[:, n])
        hit = cache[key] = (hull.vertices.copy(), H)
    return hit


def _hull_nd(points: np.ndarray, cache: dict) -> Polytope:
    """``co(points)`` for a pair's stacked points, shape ``(n_p, n)``, qhull once per shape."""
    idx, H = _hull_shape(points, cache)
    h = np.max(points @ H.T, axis=0)
    H2, h2 = _unique_rows(H, h)
    return Polytope(canonical_vertex_order(points[idx]), H2, h2)


def pair_hull_hreps(cells, src, dst, shape_cache: dict | None = None, padded=None) -> list:
    """An H-rep ``(H (f, n), h (f,))`` of ``P_ij`` for the pairs ``(src[k], dst[k])``, length
    ``K``: :func:`pair_hull_polytopes`' facets, without building the polytopes (n-D: qhull's
    normals once per pair shape, ``h`` the pair's own support; 1-D and 2-D: from the polytopes).
    """
    src, dst = np.asarray(src, int), np.asarray(dst, int)
    if len(src) == 0:
        return []
    if cells[0].dim <= 2:
        return [(P.H, P.h) for P in pair_hull_polytopes(cells, src, dst, shape_cache, padded)]
    cache = {} if shape_cache is None else shape_cache
    coords, counts = _stacked(cells, src, dst, padded)
    out = []
    for c, e in zip(counts, np.cumsum(counts)):
        H = _hull_shape(coords[e - c:e], cache)[1]
        out.append((H, np.max(coords[e - c:e] @ H.T, axis=0)))
    return out


def pair_hull_polytopes(cells, src, dst, shape_cache: dict | None = None, padded=None) -> list:
    """``P_ij`` as :class:`Polytope` for pairs ``(src[k], dst[k])``, length ``K``.

    Parameters
    ----------
    cells : sequence of Polytope
    src, dst : array_like of int, shape (K,)
    shape_cache : dict, optional
        n-D only: qhull answers per translation-invariant pair shape (kept by the caller).
    padded : tuple, optional
        :func:`padded_vertices` of ``cells``.
    """
    src, dst = np.asarray(src, int), np.asarray(dst, int)
    if len(src) == 0:
        return []
    if cells[0].dim == 2:
        return convex_polygons(pair_hull_geoms(cells, src, dst, padded))
    if cells[0].dim == 1:
        return [convex_hull_of(cells[i], cells[j]) for i, j in zip(np.minimum(src, dst), np.maximum(src, dst))]
    cache = {} if shape_cache is None else shape_cache
    coords, counts = _stacked(cells, src, dst, padded)
    ends = np.cumsum(counts)
    return [_hull_nd(coords[e - c:e], cache) for c, e in zip(counts, ends)]
