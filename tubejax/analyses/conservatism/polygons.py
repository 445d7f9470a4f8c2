"""Planar set operations for the reach-avoid limit: Minkowski sums and Pontryagin differences of
non-convex polygons with convex ones, and the robust predecessor (docs/math/limit.md#computing-it-in-2-d).
Sets are regularized shapely (multi)polygons, convex operands vertex arrays ``K (k, 2)``; ``W`` and
``−B U`` are scaled by ``SLACK`` so every rounding makes ``Pre`` larger (docs/math/limit.md#rounding).
"""

from __future__ import annotations

import numpy as np
import shapely
from shapely import affinity

from ...model.geometry import Ball, Polytope

__all__ = ["SLACK", "DEFAULT_SIDES", "disturbance_polygon", "simplify_tolerance", "tidy", "input_polygon", "polygonal", "minkowski_sum",
           "pontryagin_difference", "robust_pre", "boundary_edges"]

#: Relative scaling of ``W`` (down) and ``−B U`` (up) that keeps every rounding on the outer side.
SLACK = 1e-9
#: Sides of the regular polygon inscribed in a ball ``W`` (a power of two: finer ones contain it).
DEFAULT_SIDES = 32


def disturbance_polygon(W, sides: int = DEFAULT_SIDES) -> np.ndarray:
    """An inner polygon of ``W`` scaled by ``1 - SLACK``: vertices of shape ``(k, 2)``.

    A :class:`Ball` of radius ``r`` gives the regular ``sides``-gon inscribed in it, its vertices
    at the angles ``2 pi k / sides`` (so that a ``sides``-gon is contained in every ``m``-gon with
    ``sides | m``); radius 0 gives the point ``0``. A :class:`Polytope` gives its own vertices.

    Raises
    ------
    ValueError
        ``W`` is not 2-D, or ``sides < 3``.
    """
    if isinstance(W, Ball):
        if W.dim != 2:
            raise ValueError(f"W: the limit is computed in 2-D, got a ball in R^{W.dim}")
        if isinstance(sides, bool) or not isinstance(sides, (int, np.integer)) or sides < 3:
            raise ValueError(f"sides: the inscribed polygon of a ball needs an integer >= 3 sides, got {sides!r}")
        if W.radius == 0.0:
            return np.zeros((1, 2))
        t = 2.0 * np.pi * np.arange(int(sides)) / int(sides)
        V = W.radius * np.stack([np.cos(t), np.sin(t)], axis=1)
    elif isinstance(W, Polytope):
        if W.dim != 2:
            raise ValueError(f"W: the limit is computed in 2-D, got a polytope in R^{W.dim}")
        V = np.asarray(W.vertices, float)
    else:
        raise ValueError(f"W: expected a Ball or a Polytope, got {type(W).__name__}")
    return (1.0 - SLACK) * V


def simplify_tolerance(W_poly: np.ndarray) -> float:
    """How far :func:`tidy` may move a boundary and lose nothing in the next ``Pre``: ``SLACK / 2`` times the
    inradius of ``co(W_poly)`` about the origin (0 when the origin is on its boundary or ``W`` is a point;
    docs/math/limit.md#what-is-approximated-and-in-which-direction)."""
    W_poly = np.asarray(W_poly, float).reshape(-1, 2)
    if W_poly.shape[0] < 3:
        return 0.0
    hull = shapely.convex_hull(shapely.multipoints(W_poly))
    if hull.geom_type != "Polygon" or not hull.covers(shapely.Point(0.0, 0.0)):
        return 0.0
    return 0.5 * SLACK / (1.0 - SLACK) * float(hull.exterior.distance(shapely.Point(0.0, 0.0)))


def tidy(geom, eta: float):
    """``geom`` with collinear and nearly collinear vertices removed (Douglas-Peucker, topology
    kept, tolerance ``eta`` from :func:`simplify_tolerance`): the unions and intersections of the
    iteration leave many, and each one costs every later operation."""
    return polygonal(shapely.simplify(polygonal(geom), float(eta), preserve_topology=True))


def input_polygon(B, U: Polytope) -> np.ndarray:
    """Vertices of ``−B U`` scaled by ``1 + SLACK``, shape ``(k, 2)`` (the hull is meant; exact for
    a polytope ``U``, so ``U`` needs no circumscribed polygon)."""
    B = np.asarray(B, float)
    if not isinstance(U, Polytope):
        raise ValueError(f"U: expected a Polytope, got {type(U).__name__}")
    if B.shape != (2, U.dim):
        raise ValueError(f"B: expected shape (2, {U.dim}) for a 2-D state and U in R^{U.dim}, got {B.shape}")
    return -(1.0 + SLACK) * (np.asarray(U.vertices, float) @ B.T)


def polygonal(geom):
    """The polygons of ``geom`` (a shapely geometry) as one (multi)polygon, lower-dimensional pieces dropped."""
    if geom is None or geom.is_empty:
        return shapely.Polygon()
    if isinstance(geom, (shapely.Polygon, shapely.MultiPolygon)):
        return geom
    parts = [p for p in shapely.get_parts(geom) if isinstance(p, (shapely.Polygon, shapely.MultiPolygon))]
    return shapely.union_all(parts) if parts else shapely.Polygon()


def boundary_edges(geom) -> np.ndarray:
    """Every edge of the boundary of a (multi)polygon (exteriors and holes), shape ``(E, 2, 2)``."""
    geom = polygonal(geom)
    if geom.is_empty:
        return np.zeros((0, 2, 2))
    rings = shapely.get_rings(shapely.get_parts(geom))
    coords, index = shapely.get_coordinates(rings, return_index=True)
    same = index[1:] == index[:-1]                     # consecutive points of one closed ring
    return np.stack([coords[:-1][same], coords[1:][same]], axis=1)


def _edge_hulls(edges: np.ndarray, K: np.ndarray):
    """``conv(e ⊕ K)`` for every edge, unioned; ``edges (E, 2, 2)``, ``K (k, 2)``."""
    if edges.shape[0] == 0:
        return shapely.Polygon()
    pts = (edges[:, :, None, :] + K[None, None, :, :]).reshape(edges.shape[0], -1, 2)   # (E, 2k, 2)
    idx = np.repeat(np.arange(edges.shape[0]), pts.shape[1])
    hulls = shapely.convex_hull(shapely.multipoints(pts.reshape(-1, 2), indices=idx))
    hulls = hulls[shapely.get_type_id(hulls) == 3]        # polygons (a degenerate K gives segments: no area)
    return polygonal(shapely.union_all(hulls)) if len(hulls) else shapely.Polygon()


def minkowski_sum(geom, K: np.ndarray):
    """``geom ⊕ co(K)``: ``(geom + K[0]) ∪ ⋃_e conv(e ⊕ K)``, ``e`` over the edges of ``∂geom``
    (docs/math/limit.md#computing-it-in-2-d).

    Parameters
    ----------
    geom : shapely (Multi)Polygon
        Any polygons, non-convex, with holes.
    K : ndarray, shape (k, 2)
        Vertices of the convex operand (``k = 1``: a translation).

    Returns
    -------
    shapely (Multi)Polygon
    """
    K = np.asarray(K, float).reshape(-1, 2)
    geom = polygonal(geom)
    if geom.is_empty:
        return geom
    moved = affinity.translate(geom, float(K[0, 0]), float(K[0, 1]))
    if K.shape[0] == 1:
        return moved
    return polygonal(shapely.union_all([moved, _edge_hulls(boundary_edges(geom), K)]))


def pontryagin_difference(geom, K: np.ndarray):
    """``geom ⊖ co(K) = {x : x + co(K) ⊆ geom}`` for ``0 ∈ co(K)``: ``geom \\ ⋃_e conv(e ⊕ (−K))``
    (Lemma 6 of docs/math/limit.md#computing-it-in-2-d).

    Parameters
    ----------
    geom : shapely (Multi)Polygon
    K : ndarray, shape (k, 2)
        Vertices of a convex set containing the origin (``k = 1``: the origin itself).

    Returns
    -------
    shapely (Multi)Polygon
    """
    K = np.asarray(K, float).reshape(-1, 2)
    geom = polygonal(geom)
    if geom.is_empty or (K.shape[0] == 1 and not K.any()):
        return geom
    return polygonal(shapely.difference(geom, _edge_hulls(boundary_edges(geom), -K)))


def robust_pre(geom, Ainv: np.ndarray | None, W_poly: np.ndarray, BU_poly: np.ndarray):
    """``Pre(R) = A^{-1}((R ⊖ W) ⊕ (−B U))`` with the polygons of :func:`disturbance_polygon` and
    :func:`input_polygon`; ``Ainv = None`` stands for ``A = I``.

    Returns
    -------
    shapely (Multi)Polygon
        A superset of the exact ``Pre`` (docs/math/limit.md#rounding).
    """
    Y = minkowski_sum(pontryagin_difference(geom, W_poly), BU_poly)
    if Ainv is None or Y.is_empty:
        return Y
    a, b, c, d = (float(v) for v in np.asarray(Ainv, float).ravel())
    return polygonal(affinity.affine_transform(Y, [a, b, c, d, 0.0, 0.0]))
