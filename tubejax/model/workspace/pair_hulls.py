"""Pair hulls ``P_ij = co(P_i u P_j)`` of many pairs at once (docs/math/problem-data.md).

In 2-D, Andrew's monotone chain over all pairs with the same point count, each orientation decided
exactly (:func:`convex_hull_rings`), bit-identical to :meth:`Polytope.from_convex_polygon` of GEOS's
hull. In n-D, qhull (two boxes in 5-D and up: the elimination of
:mod:`~tubejax.model.geometry.box_pair_hull`) once per *shape*: pairs whose stacked vertices differ by a
translation share extreme points and normals, and each pair's offsets are its own support values.
Points are stacked ``P_min(i,j)`` then ``P_max(i,j)``, so ``P_ij`` and ``P_ji`` are the same polytope.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import shapely
from scipy.spatial import ConvexHull

from ..geometry import Polytope, convex_hull_of
from ..geometry.box_pair_hull import box_pair_hull
from ..geometry.polytope import _unique_rows, canonical_vertex_order, first_distinct_rows
from .rectilinear import polygon_vertices

__all__ = ["convex_polygons", "convex_hull_rings", "padded_vertices", "pair_hull_geoms", "geos_pair_hull_geoms",
           "pair_hull_polytopes", "pair_hull_hreps"]

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
    """2-D: the shapely polygons of ``P_ij`` for pairs ``(src[k], dst[k])``, shape ``(K,)``: the
    rings of :func:`convex_hull_rings` (GEOS's vertices, counter-clockwise), GEOS's own hull for
    the degenerate ones it leaves (:func:`geos_pair_hull_geoms`).

    ``padded``: :func:`padded_vertices` of ``cells``, if the caller keeps it.
    """
    src, dst = np.asarray(src, int), np.asarray(dst, int)
    out = np.empty(len(src), dtype=object)
    if len(src) == 0:
        return out
    rings, left = _pair_rings(cells, src, dst, padded)
    for ks, V in rings:
        out[ks] = shapely.polygons(V)
    if left.size:
        out[left] = geos_pair_hull_geoms(cells, src[left], dst[left], padded)
    return out


def _pair_rings(cells, src, dst, padded=None) -> tuple[list, np.ndarray]:
    """:func:`convex_hull_rings` of each pair's stacked points, pairs grouped by point count:
    ``([(pair indices (g,), rings (g, c, 2)), ...], the pairs left to GEOS, sorted)``."""
    coords, counts = _stacked(cells, src, dst, padded)
    starts = np.cumsum(counts) - counts
    out, left = [], []
    for P in np.unique(counts):
        ks = np.flatnonzero(counts == P)
        rings, rest = convex_hull_rings(coords[starts[ks][:, None] + np.arange(P)[None, :]])
        out += [(ks[sub], V) for sub, V in rings]
        left.extend(ks[rest].tolist())
    return out, np.sort(np.array(left, dtype=np.int64))


def geos_pair_hull_geoms(cells, src, dst, padded=None) -> np.ndarray:
    """:func:`pair_hull_geoms` by GEOS alone: one vectorised ``convex_hull`` over
    ``multipoints(..., indices=)`` (the reference, and the degenerate pairs)."""
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
    V, n = polygon_vertices(geoms)
    out = [None] * len(geoms)
    for c in np.unique(n):
        ks = np.flatnonzero(n == c)
        if c < 3:
            raise ValueError(f"a pair hull is degenerate ({c} vertices)")
        _ring_polytopes(V[ks, :c], ks, out)
    return out


def _ring_polytopes(V: np.ndarray, ks: np.ndarray, out: list) -> None:
    """``out[ks[r]] = Polytope`` of the convex ring ``V[r]`` (``V (g, m, 2)``, either orientation,
    any start, no collinear points): counter-clockwise from its lowest point, as
    ``Polytope.from_convex_polygon``."""
    m = V.shape[1]
    area2 = np.sum(V[:, :, 0] * np.roll(V[:, :, 1], -1, axis=1)
                   - np.roll(V[:, :, 0], -1, axis=1) * V[:, :, 1], axis=1)
    V = np.where((area2 < 0)[:, None, None], V[:, ::-1], V)
    start = np.lexsort((np.round(V[:, :, 0], 12), np.round(V[:, :, 1], 12)), axis=-1)[:, 0]
    ext = np.take_along_axis(V, ((np.arange(m)[None, :] + start[:, None]) % m)[:, :, None], axis=1)
    e = np.roll(ext, -1, axis=1) - ext
    H = np.stack([e[:, :, 1], -e[:, :, 0]], axis=2)
    H /= np.linalg.norm(H, axis=2, keepdims=True)
    h = np.einsum("bij,bij->bi", H, ext)
    for r, k in enumerate(ks):
        out[k] = Polytope(ext[r], H[r], h[r])


#: Shewchuk's first error bound of the 2-D orientation determinant, ``(3 + 16 u) u``.
_CCW_ERR = (3.0 + 16.0 * 2.0 ** -53) * 2.0 ** -53
#: Products below this may have lost bits to underflow: the filter does not decide them.
_TINY = 2.0 ** -900


def _exact_orientation(a, b, c) -> int:
    """The sign of ``(a - c) x (b - c)`` in exact rational arithmetic (points as float pairs)."""
    (ax, ay), (bx, by), (cx, cy) = ([Fraction(float(v)) for v in p] for p in (a, b, c))
    det = (ax - cx) * (by - cy) - (ay - cy) * (bx - cx)
    return (det > 0) - (det < 0)


def _orientation(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """The sign of ``(a - c) x (b - c)`` (``> 0``: ``a, b, c`` turn left) for points ``(K, 2)``,
    exactly: Shewchuk's filter (``orient2d``'s first stage) decides where the float determinant's
    sign is certain, exact rationals the rest (collinear points, near-collinear ones)."""
    left = (a[:, 0] - c[:, 0]) * (b[:, 1] - c[:, 1])
    right = (a[:, 1] - c[:, 1]) * (b[:, 0] - c[:, 0])
    det = left - right
    mixed = (left == 0) | (right == 0) | ((left > 0) != (right > 0))          # no cancellation
    small = ((left != 0) & (np.abs(left) < _TINY)) | ((right != 0) & (np.abs(right) < _TINY))
    sure = (mixed | (np.abs(det) > _CCW_ERR * (np.abs(left) + np.abs(right)))) & ~small & np.isfinite(det)
    sign = np.sign(det)
    for k in np.flatnonzero(~sure).tolist():
        sign[k] = _exact_orientation(a[k], b[k], c[k])
    return sign


def _chain(S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Andrew's monotone chain over points sorted along ``x`` (``S (K, P, 2)``, finite), every
    ``K`` at once: the indices of the left-turning chain ``(K, P)`` and its lengths ``(K,)``.
    Collinear and repeated points are dropped (orientations decided exactly)."""
    K, P = S.shape[:2]
    st = np.zeros((K, P), dtype=np.int64)
    top = np.zeros(K, dtype=np.int64)
    for i in range(P):
        while True:
            rows = np.flatnonzero(top >= 2)
            if rows.size == 0:
                break
            a = S[rows, st[rows, top[rows] - 2]]
            b = S[rows, st[rows, top[rows] - 1]]
            pop = rows[_orientation(a, b, S[rows, i]) <= 0]
            if pop.size == 0:
                break
            top[pop] -= 1
        st[np.arange(K), top] = i
        top += 1
    return st, top


def convex_hull_rings(points: np.ndarray) -> tuple[list, np.ndarray]:
    """The convex hulls of ``K`` point sets of ``P`` points each, ``points (K, P, 2)``, vectorised.

    Returns
    -------
    rings : list of ``(ks, V)``
        The hulls with ``c`` vertices: ``ks (g,)`` which sets, ``V (g, c, 2)`` their extreme points
        counter-clockwise (collinear and repeated points dropped).
    left : ndarray of int
        The sets with a non-finite point or whose hull has fewer than 3 vertices (not in ``rings``).
    """
    K, P = points.shape[:2]
    finite = np.all(np.isfinite(points), axis=(1, 2))
    points = np.where(finite[:, None, None], points, 0.0)
    order = np.lexsort((points[:, :, 1], points[:, :, 0]), axis=-1)
    S = np.take_along_axis(points, order[:, :, None], axis=1)
    lo, n_lo = _chain(S)
    up, n_up = _chain(S[:, ::-1])
    count = n_lo + n_up - 2
    good = finite & (count >= 3)
    rings = []
    for c in np.unique(count[good]):
        ks = np.flatnonzero(good & (count == c))
        j = np.arange(c)[None, :]
        a = (n_lo[ks] - 1)[:, None]                     # the lower chain without its last point,
        idx = np.where(j < a, np.take_along_axis(lo[ks], np.minimum(j, P - 1), axis=1),    # then the upper one
                       P - 1 - np.take_along_axis(up[ks], np.clip(j - a, 0, P - 1), axis=1))
        rings.append((ks, np.take_along_axis(S[ks], idx[:, :, None], axis=1)))
    return rings, np.flatnonzero(~good)


def _hull_shape(points: np.ndarray, cache: dict) -> tuple:
    """The hull of a pair's stacked points ``(n_p, n)``, once per shape (two boxes in 5-D and up:
    :func:`~tubejax.model.geometry.box_pair_hull.box_pair_hull`, else qhull): ``(vertex
    indices, unique facet normals (f, n), whether the normals are distinct when rounded as
    :func:`~tubejax.model.geometry.polytope.first_distinct_rows` rounds)`` (then so are the rows of
    ``(H, h)`` for any ``h``: no pair of the shape has rows to merge)."""
    rel = points - points[0]
    scale = max(float(np.max(np.abs(rel))), 1e-300)
    key = (points.shape, np.round(rel / scale, _SHAPE_KEY_DECIMALS).tobytes())
    hit = cache.get(key)
    if hit is None:
        boxes = box_pair_hull(points)
        if boxes is not None:
            idx, H = boxes
        else:
            n = points.shape[1]
            hull = ConvexHull(points)
            E = hull.equations
            idx, H = hull.vertices.copy(), E[:, :n][first_distinct_rows(np.hstack([E[:, :n], -E[:, n:]]))]
        hit = cache[key] = (idx, H, first_distinct_rows(H).size == len(H))
    return hit


def _hull_nd(points: np.ndarray, cache: dict) -> Polytope:
    """``co(points)`` for a pair's stacked points, shape ``(n_p, n)``, qhull once per shape."""
    idx, H, distinct = _hull_shape(points, cache)
    h = np.max(points @ H.T, axis=0)
    H2, h2 = (H.copy(), h) if distinct else _unique_rows(H, h)
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
    if np.all(counts == counts[0]):
        return _equal_count_hreps(coords.reshape(len(counts), counts[0], -1), cache)
    out = []
    for c, e in zip(counts, np.cumsum(counts)):
        H = _hull_shape(coords[e - c:e], cache)[1]
        out.append((H, np.max(coords[e - c:e] @ H.T, axis=0)))
    return out


def _equal_count_hreps(X: np.ndarray, cache: dict) -> list:
    """:func:`pair_hull_hreps` for pairs of equally many stacked points, ``X (K, n_p, n)``: the
    shape keys of :func:`_hull_shape` for all pairs at once, then qhull (or the cache) once per
    key, in the pairs' order, and the ``h`` of a key's pairs in one product. The same arrays as
    pair by pair."""
    rel = X - X[:, :1]
    scale = np.maximum(np.max(np.abs(rel), axis=(1, 2)), 1e-300)
    keys = np.round(rel / scale[:, None, None], _SHAPE_KEY_DECIMALS)
    groups: dict = {}
    for k in range(len(X)):
        groups.setdefault(keys[k].tobytes(), []).append(k)
    out: list = [None] * len(X)
    for ks in groups.values():
        H = _hull_shape(X[ks[0]], cache)[1]
        h = np.max(np.matmul(X[ks], H.T), axis=1)
        for k, hk in zip(ks, h):
            out[k] = (H, hk)
    return out


def _pair_polygons(cells, src, dst, padded=None) -> list:
    """2-D pair hulls as :class:`Polytope`: :func:`convex_hull_rings` of each pair's points, GEOS
    (:func:`pair_hull_geoms`, which raises for them) for the degenerate ones it leaves; the same
    polytopes as GEOS's hulls through :func:`convex_polygons` (both keep exactly the strictly
    extreme points, in exact orientation tests)."""
    out: list = [None] * len(src)
    rings, left = _pair_rings(cells, src, dst, padded)
    for ks, V in rings:
        _ring_polytopes(V, ks, out)
    if left.size:
        for k, P in zip(left.tolist(), convex_polygons(geos_pair_hull_geoms(cells, src[left], dst[left], padded))):
            out[k] = P
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
        return _pair_polygons(cells, src, dst, padded)
    if cells[0].dim == 1:
        return [convex_hull_of(cells[i], cells[j]) for i, j in zip(np.minimum(src, dst), np.maximum(src, dst))]
    cache = {} if shape_cache is None else shape_cache
    coords, counts = _stacked(cells, src, dst, padded)
    ends = np.cumsum(counts)
    return [_hull_nd(coords[e - c:e], cache) for c, e in zip(counts, ends)]
