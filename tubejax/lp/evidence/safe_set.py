"""Exact proofs that a safe set ``S`` avoids the obstacles' interiors (docs/math/evidence.md#proof-levels).

A tube proven to stay in ``S`` is safe only if ``int S`` does not meet ``int O``. Every obstacle is
split into convex pieces whose union is exactly it (a 2-D polygon by
``shapely.constrained_delaunay_triangles``, the tiling verified exactly by
:func:`_verify_triangulation`: positive orientations, edges adding up to the oriented boundary).
Each piece whose bounding box overlaps ``S``'s must be separated from ``S`` by a hyperplane checked
exactly, ``max_S a.x <= min_piece a.x``, with ``a`` from both sets' exact facet normals (complete in
2-D by the separating axis theorem), then a float LP's separating direction. Otherwise ``S`` is not
proven and its edges keep the float level.
"""

from __future__ import annotations

from collections import Counter
from fractions import Fraction
from typing import NamedTuple

import numpy as np
import shapely
from scipy.optimize import linprog

from ...model.geometry import Polytope
from .exact_geometry import ExactGeometryError, ExactPolytope, _cross, exact_hull
from .exact_problem import _cached, _fkey, exact_polytope
from .rational import QArray, snap_rational

__all__ = ["ObstaclePieces", "obstacle_pieces", "prove_safe_set", "separated"]


class ObstaclePieces(NamedTuple):
    """Convex pieces whose union is exactly the obstacle set.

    Attributes
    ----------
    pieces : list of ExactPolytope
    lo, hi : ndarray, shape (n_pieces, n)   float bounding boxes (exact: vertex coordinates)
    failure : str                            why the split could not be verified ('' if it was)
    tree : shapely.STRtree or None
        The boxes' first two axes (``n >= 2``), to propose the pieces a box can meet
        (:func:`near_pieces`).
    """

    pieces: list
    lo: np.ndarray
    hi: np.ndarray
    failure: str
    tree: object = None


def near_pieces(ob: ObstaclePieces, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The pieces whose bounding box meets the open box ``(lo, hi)`` (``(n,)`` each) with interior,
    in increasing order: ``lo_k < hi`` and ``lo < hi_k`` on every axis (exact float comparisons;
    the tree only proposes pieces whose boxes touch on the first two axes, a superset)."""
    cand = ob.tree.query(shapely.box(lo[0], lo[1], hi[0], hi[1])) if ob.tree is not None \
        else np.arange(ob.lo.shape[0])
    cand = np.sort(np.asarray(cand, dtype=np.int64))
    return cand[np.all(ob.lo[cand] < hi, axis=1) & np.all(lo < ob.hi[cand], axis=1)]


def _ring_edges(coords: np.ndarray) -> list:
    pts = [tuple(p) for p in coords.tolist()]
    if pts and pts[0] == pts[-1]:
        pts = pts[:-1]
    return list(zip(pts, pts[1:] + pts[:1]))


def _orient(a, b, c) -> Fraction:
    return _cross(*(tuple(map(Fraction, p)) for p in (a, b, c)))


def _verify_triangulation(poly: shapely.Polygon, tris: list) -> str:
    """'' when the triangles (lists of 3 float points) tile ``poly`` exactly, else why not."""
    flow = Counter()
    for t in tris:
        if _orient(*t) < 0:
            t = [t[0], t[2], t[1]]
        if _orient(*t) == 0:
            return "a degenerate triangle"
        for a, b in zip(t, t[1:] + t[:1]):
            flow[(a, b)] += 1
            flow[(b, a)] -= 1
    poly = shapely.orient_polygons(poly, exterior_cw=False)   # exterior CCW, holes CW
    rings = [poly.exterior] + list(poly.interiors)
    for ring in rings:
        for a, b in _ring_edges(np.asarray(ring.coords, float)):
            flow[(a, b)] -= 1
            flow[(b, a)] += 1
    if any(v != 0 for v in flow.values()):
        return "the triangles do not add up to the polygon's boundary"
    return ""


def _polygon_pieces(poly: shapely.Polygon) -> tuple[list, str]:
    tri = shapely.constrained_delaunay_triangles(poly)
    tris = []
    for g in shapely.get_parts(tri):
        c = np.asarray(shapely.get_coordinates(g), float)[:3]
        tris.append([tuple(p) for p in c.tolist()])
    why = _verify_triangulation(poly, tris)
    return ([np.array(t, float) for t in tris], why)


def _pieces_of(o) -> tuple[list, str]:
    """Float vertex arrays of convex pieces of one obstacle, and a failure reason."""
    if isinstance(o, Polytope):
        return [np.asarray(o.vertices, float)], ""
    if isinstance(o, shapely.Polygon):
        return _polygon_pieces(o)
    if isinstance(o, shapely.MultiPolygon):
        out = []
        for p in o.geoms:
            ps, why = _polygon_pieces(p)
            if why:
                return [], why
            out.extend(ps)
        return out, ""
    return [], f"obstacle of type {type(o).__name__} cannot be split into convex pieces"


#: ``id(obstacles) -> (obstacles, key)``: the key of a decomposition's obstacles, made once, so
#: every cached proof refers to one key instead of a WKB of every obstacle per edge.
_OBSTACLE_KEYS: dict = {}


def _obstacles_key(obstacles) -> tuple:
    hit = _OBSTACLE_KEYS.get(id(obstacles))
    if hit is not None and hit[0] is obstacles:
        return hit[1]
    key = tuple(("poly",) + _fkey(o.vertices) if isinstance(o, Polytope)
                else ("wkb", shapely.to_wkb(o)) for o in obstacles)
    if isinstance(obstacles, tuple):                 # immutable: its key cannot change
        if len(_OBSTACLE_KEYS) >= 64:
            _OBSTACLE_KEYS.clear()
        _OBSTACLE_KEYS[id(obstacles)] = (obstacles, key)
    return key


def obstacle_pieces(obstacles) -> ObstaclePieces:
    """Convex pieces of every obstacle, exactly verified (cached by the obstacles' data)."""

    def make():
        pieces, los, his = [], [], []
        for o in obstacles:
            arrs, why = _pieces_of(o)
            if why:
                return ObstaclePieces([], np.zeros((0, 1)), np.zeros((0, 1)), why)
            for V in arrs:
                try:
                    pieces.append(exact_hull(QArray.from_floats(V)))
                except ExactGeometryError as exc:
                    return ObstaclePieces([], np.zeros((0, 1)), np.zeros((0, 1)), f"obstacle piece: {exc}")
                los.append(V.min(axis=0))
                his.append(V.max(axis=0))
        n = los[0].shape[0] if los else 1
        lo, hi = np.array(los).reshape(-1, n), np.array(his).reshape(-1, n)
        tree = shapely.STRtree(shapely.box(lo[:, 0], lo[:, 1], hi[:, 0], hi[:, 1])) if n >= 2 and len(lo) else None
        return ObstaclePieces(pieces, lo, hi, "", tree)

    return _cached(("obstacles", _obstacles_key(obstacles)), make)


def _max_min(P: ExactPolytope, a: list) -> tuple[Fraction, Fraction]:
    vals = [sum(x * y for x, y in zip(a, v)) for v in P.V.num.tolist()]
    return Fraction(max(vals), P.V.den), Fraction(min(vals), P.V.den)


def _separates(S: ExactPolytope, O: ExactPolytope, a: list) -> bool:
    """``max_S a.x <= min_O a.x`` or the same with ``-a`` (exact)."""
    s_hi, s_lo = _max_min(S, a)
    o_hi, o_lo = _max_min(O, a)
    return s_hi <= o_lo or o_hi <= s_lo


def _lp_normal(S: ExactPolytope, O: ExactPolytope):
    """A candidate separating normal from a float LP (``None`` if the LP finds none)."""
    Vs, Vo = S.V.to_float(), O.V.to_float()
    n = Vs.shape[1]
    # variables (a, b, delta): a.s - b + delta <= 0, -a.o + b + delta <= 0, |a_i| <= 1, max delta
    A = np.vstack([np.hstack([Vs, -np.ones((len(Vs), 1)), np.ones((len(Vs), 1))]),
                   np.hstack([-Vo, np.ones((len(Vo), 1)), np.ones((len(Vo), 1))])])
    c = np.zeros(n + 2)
    c[-1] = -1.0
    res = linprog(c, A_ub=A, b_ub=np.zeros(len(A)), bounds=[(-1, 1)] * n + [(None, None), (None, 1)],
                  method="highs")
    if res.status != 0 or res.x[-1] < -1e-9:
        return None
    return [snap_rational(v) for v in res.x[:n]]


def separated(S: ExactPolytope, O: ExactPolytope) -> bool:
    """Whether ``int S`` and ``int O`` are proven disjoint exactly (see the module doc)."""
    for P in (S, O):
        for a in P.H.tolist():
            if _separates(S, O, a):
                return True
    if S.dim <= 2:
        return False                       # the facet normals are complete in 2-D
    a = _lp_normal(S, O)
    return a is not None and any(a) and _separates(S, O, a)


def prove_safe_set(S, obstacles) -> tuple[bool, str]:
    """Prove ``int S ∩ int O = ∅`` exactly.

    Parameters
    ----------
    S : Polytope           the safe set (its exact float vertices)
    obstacles : sequence   the decomposition's obstacles (Polytopes and/or shapely polygons)

    Returns
    -------
    (bool, str)
        ``True`` and ``''`` when proven; ``False`` and the reason otherwise. Cached per
        ``(S, obstacles)``.
    """
    if not obstacles:
        return True, ""
    ob = obstacle_pieces(obstacles)
    if ob.failure:
        return False, f"obstacles not split exactly: {ob.failure}"

    def make():
        lo, hi = np.asarray(S.vertices, float).min(axis=0), np.asarray(S.vertices, float).max(axis=0)
        if ob.lo.shape[1] != lo.shape[0]:
            return False, f"obstacles in R^{ob.lo.shape[1]}, safe set in R^{lo.shape[0]}"
        near = near_pieces(ob, lo, hi)
        if near.size == 0:
            return True, ""
        try:
            Sx = exact_polytope(S)
        except ExactGeometryError as exc:
            return False, f"safe set: {exc}"
        for k in near.tolist():
            if not separated(Sx, ob.pieces[k]):
                return False, f"no exact separating hyperplane from obstacle piece {k}"
        return True, ""

    return _cached(("safe",) + _fkey(S.vertices) + (_obstacles_key(obstacles),), make)
