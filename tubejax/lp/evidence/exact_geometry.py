"""Exact facets of convex polytopes from rational vertices, and their exact support functions.

The float H-reps are never used for a proof. :func:`exact_hull` recomputes the facets of ``co(V)``:
1-D ``[min V, max V]``; 2-D Andrew's monotone chain with exact orientation tests; n-D qhull proposes
hyperplanes, each checked exactly, none missing (:func:`_check_closed`,
docs/math/evidence.md#proof-levels). :func:`exact_hull_in_order` orders them as given float rows.
Rows are primitive integer vectors; ``scale`` holds each row's largest absolute entry.
"""

from __future__ import annotations

import math
from operator import mul
from typing import NamedTuple

import flint
import numpy as np
from scipy.spatial import ConvexHull

from .rational import QArray, int_matrix, int_products

__all__ = ["ExactPolytope", "ExactGeometryError", "exact_hull", "exact_hull_in_order", "rows_facets",
           "exact_halfspaces", "exact_support", "ccw_ring", "polytope_of_facets", "independent_points"]


class ExactGeometryError(ValueError):
    """The exact facets of a polytope could not be established."""


class ExactPolytope(NamedTuple):
    """``co(V) = {x : H x <= h}`` in exact arithmetic.

    Attributes
    ----------
    V : QArray, shape (n_v, n)       the given vertices, in the given order
    H : ndarray of object ints, shape (n_f, n)   primitive integer facet normals
    h : QArray, shape (n_f,)         facet offsets
    scale : ndarray of object ints, shape (n_f,)  ``max_i |H[f, i]|`` (> 0)
    """

    V: QArray
    H: np.ndarray
    h: QArray
    scale: np.ndarray

    @property
    def dim(self) -> int:
        return int(self.V.shape[1])

    def bounding_box(self) -> tuple[np.ndarray, np.ndarray]:
        """Exact bounding box ``(lo, hi)``: object arrays of Fractions, shape ``(n,)``."""
        F = self.V.to_fractions()
        return (np.array([min(F[:, d]) for d in range(self.dim)], dtype=object),
                np.array([max(F[:, d]) for d in range(self.dim)], dtype=object))


def _primitive(a: list[int]) -> list[int]:
    g = math.gcd(*a)
    return [v // g for v in a] if g > 1 else list(a)


def polytope_of_facets(V: QArray, rows: list[list[int]], offs: list[int]) -> ExactPolytope:
    """Facets ``rows . x_num <= offs`` (numerator units of ``V``) -> :class:`ExactPolytope`."""
    H = np.array(rows, dtype=object).reshape(len(rows), V.shape[1])
    h = QArray(np.array(offs, dtype=object), V.den).reduced()
    scale = np.array([max(abs(v) for v in r) for r in rows], dtype=object)
    return ExactPolytope(V, H, h, scale)


def _hull_1d(V: QArray) -> ExactPolytope:
    x = V.num[:, 0].tolist()
    lo, hi = min(x), max(x)
    if not hi > lo:
        raise ExactGeometryError("a 1-D polytope needs two distinct points")
    return polytope_of_facets(V, [[-1], [1]], [-lo, hi])


def _cross(o, a, b):
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def ccw_ring(pts: list) -> list:
    """Andrew's monotone chain over sorted points (integers: exact; floats: as they round): the
    strictly extreme ones, counter-clockwise (fewer than 3 when the points are collinear)."""
    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and _cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and _cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return lower[:-1] + upper[:-1]


def _hull_2d(V: QArray) -> ExactPolytope:
    pts = sorted(set(map(tuple, V.num.tolist())))
    if len(pts) < 3:
        raise ExactGeometryError(f"a 2-D polytope needs 3 points not on a line, got {len(pts)} distinct")
    ring = ccw_ring(pts)                           # counter-clockwise, no collinear points
    if len(ring) < 3:
        raise ExactGeometryError("the points are collinear: no 2-D polytope")
    rows, offs = [], []
    for a, b in zip(ring, ring[1:] + ring[:1]):
        nrm = _primitive([b[1] - a[1], a[0] - b[0]])   # outward for a CCW ring
        rows.append(nrm)
        offs.append(nrm[0] * a[0] + nrm[1] * a[1])
    return polytope_of_facets(V, rows, offs)


def independent_points(P: list, idx: list, k: int) -> list:
    """Up to ``k + 1`` affinely independent points among ``P[idx]`` (exact), as indices: ``idx[0]`` and
    each later point whose difference to it is independent of the earlier ones' (the greedy choice), i.e.
    the pivot columns of the differences' reduced echelon form (FLINT, integers)."""
    if len(idx) == 1:
        return [idx[0]]
    p0 = P[idx[0]]
    D = flint.fmpz_mat([[P[i][d] - p0[d] for i in idx[1:]] for d in range(len(p0))])    # (n, len(idx) - 1)
    R, _, rank = D.rref()
    pivots = [next(c for c, x in enumerate(row) if x) for row in R.tolist()[:rank]]
    return [idx[0]] + [idx[1 + c] for c in pivots[:k]]


def _facet_through(P: list, idx: list):
    """The exact hyperplane through the ``n`` affinely independent points ``P[idx]``: ``(a, b)``,
    ``a`` primitive (its sign is arbitrary: :func:`_facet_of` orients it). ``n >= 3``: the null
    space of the differences (FLINT's integer matrices; docs/explanation/performance.md#exact-facets)."""
    n, p0 = len(P[0]), P[idx[0]]
    D = [[P[v][d] - p0[d] for d in range(n)] for v in idx[1:]]          # (n-1, n)
    if n <= 2:
        a = [1] if n == 1 else [D[0][1], -D[0][0]]
    else:
        N = flint.fmpz_mat(D).nullspace()[0]
        a = [int(N[c, 0]) for c in range(n)]
    a = _primitive(a)
    return a, sum(x * y for x, y in zip(a, p0))


def _distinct(V: QArray) -> tuple[list, np.ndarray]:
    """The distinct points of ``V`` (lists of integer numerators) and their floats, shape ``(k, n)``:
    ``num / den`` by correctly rounded int division (numerators alone can overflow floats)."""
    P = [list(p) for p in dict.fromkeys(map(tuple, V.num.tolist()))]
    Pf = np.array([[x / V.den for x in p] for p in P], dtype=float)
    if not np.all(np.isfinite(Pf)):
        raise ExactGeometryError(f"the points are out of the float range in R^{V.shape[1]}")
    return P, Pf


def _facet_of(P: list, near: list, Pa: np.ndarray | None = None):
    """The exact facet through ``n`` affinely independent points among ``P[near]`` (first ones
    first), oriented so that every point lies on its inner side: ``(a, b, tight)`` (``tight``:
    frozenset of the indices on it), ``None`` when ``near`` spans less than a hyperplane;
    ExactGeometryError when points lie strictly on both sides. ``Pa``: ``P`` as an object array
    ``(k, n)`` or :func:`~.rational.int_matrix` (the sides as one integer product), when the caller has it."""
    n = len(P[0])
    pick = near[:n] if n <= 2 or not near else independent_points(P, near, n - 1)    # P distinct: any 2 independent
    if len(pick) < n:
        return None
    a, b = _facet_through(P, pick)
    if Pa is None:
        side = np.array([sum(map(mul, a, p)) - b for p in P], dtype=object)
    else:
        side = int_products(Pa, [a])[:, 0] - b
    if side.max() > 0:
        if side.min() < 0:
            raise ExactGeometryError("a proposed facet does not support the points exactly")
        a, b, side = [-x for x in a], -b, -side
    return a, b, frozenset(np.flatnonzero(side == 0).tolist())


def _hull_nd(V: QArray) -> ExactPolytope:
    """n >= 3: qhull proposes, exact arithmetic decides (see the module docstring)."""
    n = V.shape[1]
    P, Pf = _distinct(V)
    try:
        hull = ConvexHull(Pf)
    except Exception as exc:                        # QhullError for flat input
        raise ExactGeometryError(f"qhull could not build the hull in R^{n}: {exc}") from None
    scale = float(np.max(np.abs(Pf))) or 1.0
    facets, Pa = {}, int_matrix(P)                  # primitive normal -> (offset, tight indices)
    for eq in np.unique(np.round(hull.equations, 9), axis=0):
        fac = _facet_of(P, np.flatnonzero(np.abs(Pf @ eq[:n] + eq[n]) <= 1e-7 * scale).tolist(), Pa)
        if fac is not None:
            facets[tuple(fac[0])] = fac[1:]
    _check_closed(P, facets)
    return polytope_of_facets(V, [list(a) for a in facets], [b for b, _ in facets.values()])


def _check_closed(P: list, facets: dict) -> None:
    """Every ridge of every facet lies in a second facet: then no facet is missing
    (the argument: docs/math/evidence.md#proof-levels). In 2-D a facet's ridges are its two ends; in
    ``n >= 3`` they are the faces ``F ∩ G`` of dimension ``n - 2`` (:func:`_ridge_faces`), complete when
    :func:`_ridges_cover` holds: the same argument one dimension down."""
    if len(P[0]) == 2:
        tights = [t for _, t in facets.values()]
        for a, (b, tight) in facets.items():        # an edge's ridges: its two ends (distinct points)
            along = sorted(tight, key=lambda i: a[0] * P[i][1] - a[1] * P[i][0])
            for end in (along[0], along[-1]):
                if sum(end in t for t in tights) < 2:
                    raise ExactGeometryError("the proposed facets do not close up exactly (a ridge lies in one facet)")
        return
    items = list(facets.items())
    faces: dict = {}                                # ridge points -> the ridge's own facets (None: no ridge)
    for f, (aF, (_, tF)) in enumerate(items):
        ridges = []
        for g, (aG, (_, tG)) in enumerate(items):
            common = tF & tG
            if g == f or len(common) < len(aF) - 1:
                continue
            if common not in faces:
                faces[common] = _ridge_faces(P, aF, aG, common)
            if faces[common] is not None:
                ridges.append((common, faces[common]))
        if not _ridges_cover(ridges):
            raise ExactGeometryError("the proposed facets do not close up exactly (a ridge lies in one facet)")


def _ridge_faces(P: list, aF: list, aG: list, common: frozenset):
    """The facets (as sets of point indices) of ``co(P[common])``, which lies in the facets
    ``aF . x = bF`` and ``aG . x = bG``, when it has dimension ``n - 2`` (a ridge); else ``None``.

    Dropping two coordinates whose 2x2 minor of ``(aF, aG)`` is not 0 maps the flat of both
    hyperplanes one to one onto ``R^(n-2)``, so faces and dimension are those of the image,
    whose exact hull (:func:`exact_hull`) refuses less than ``n - 2`` dimensions.
    """
    n = len(aF)
    drop = next(((c, d) for c in range(n) for d in range(c + 1, n) if aF[c] * aG[d] != aF[d] * aG[c]), None)
    if drop is None:
        return None
    pts = sorted(common)
    keep = [c for c in range(n) if c not in drop]
    if n == 4:
        return _polygon_faces(pts, [(P[i][keep[0]], P[i][keep[1]]) for i in pts])
    sub = QArray(np.array([[P[i][c] for c in keep] for i in pts], dtype=object).reshape(len(pts), n - 2), 1)
    try:
        F = exact_hull(sub)
    except ExactGeometryError:
        return None
    proj = sub.num.tolist()
    return [frozenset(pts[k] for k, p in enumerate(proj) if sum(map(mul, row, p)) == off)
            for row, off in zip(F.H.tolist(), F.h.to_fractions().tolist())]


def _polygon_faces(ids: list, xy: list):
    """The edges (sets of ``ids``, collinear points included) of the hull of distinct integer
    points ``xy`` in the plane, ``None`` when they do not span it (:func:`_hull_2d`'s ring)."""
    pts = sorted(set(xy))
    ring = ccw_ring(pts) if len(pts) >= 3 else []
    if len(ring) < 3:
        return None
    return [frozenset(i for i, p in zip(ids, xy) if _cross(a, b, p) == 0) for a, b in zip(ring, ring[1:] + ring[:1])]


def _ridges_cover(ridges: list) -> bool:
    """Whether ridges ``(points, facets)`` of one facet ``F`` are all of its ridges: there is one,
    and each facet of each lies in a second one (the ridges of ``F`` meet two by two along
    those faces, and their adjacency graph is connected)."""
    return bool(ridges) and all(sum(face <= other for other, _ in ridges) >= 2
                                for _, faces in ridges for face in faces)


def exact_hull(V) -> ExactPolytope:
    """Exact facets of ``co(V)``.

    Parameters
    ----------
    V : QArray or float array, shape (n_v, n)
        Floats are taken at their exact values.

    Returns
    -------
    ExactPolytope

    Raises
    ------
    ExactGeometryError
        When the points do not span ``R^n`` or (n >= 3) qhull's facets fail the exact checks.
    """
    V = QArray.coerce(V)
    if V.num.ndim != 2 or V.shape[0] == 0:
        raise ExactGeometryError(f"vertices must have shape (n_v, n), got {V.shape}")
    n = V.shape[1]
    if n == 1:
        return _hull_1d(V)
    if n == 2:
        return _hull_2d(V)
    return _hull_nd(V)


IN_ORDER_TOL = 1e-9       #: a point is near a float facet within this times the points' extent


def rows_facets(V, H, h) -> tuple[list, list]:
    """:func:`exact_hull_in_order` but the check that no facet is missing: ``(P, found)``, the
    distinct points of ``V`` (lists of integer numerators over ``V.den``) and, per row, ``(a, b,
    tight)``: a facet ``a . x_num <= b`` of ``co(V)`` whose unit normal is the row's to
    :data:`IN_ORDER_TOL`, and the indices of the points on it. ExactGeometryError when a row has none."""
    V, H, h = QArray.coerce(V), np.asarray(H, dtype=float), np.asarray(h, dtype=float)
    if V.num.ndim != 2 or not V.shape[0] or h.ndim != 1 or not h.size or H.shape != (h.size, V.shape[1]):
        raise ExactGeometryError(f"need points (n_v, n), rows (n_f, n), (n_f,); got {V.shape}, {H.shape}, {h.shape}")
    n, (P, Pf), nrm = V.shape[1], _distinct(V), np.sqrt(np.einsum("ij,ij->i", H, H))
    if not (np.all((nrm > 0) & (nrm < np.inf)) and np.isfinite(h).all()):      # NaN fails too
        raise ExactGeometryError("the float rows must be finite and nonzero")
    Hu, hu = H / nrm[:, None], h / nrm
    res = np.abs(Hu @ Pf.T - hu[:, None])                                # (n_f, n_p)
    tol = IN_ORDER_TOL * float(np.max(np.ptp(Pf, axis=0))) + 64 * np.finfo(float).eps * float(np.max(np.abs(Pf)))
    nearest, within = np.argsort(res, axis=1, kind="stable").tolist(), (res <= tol).tolist()
    found, Pa = [], int_matrix(P) if n >= 3 else None      # 1-D, 2-D: a few points, lists are faster
    for f, row in enumerate(Hu.tolist()):
        fac = _facet_of(P, [i for i in nearest[f] if within[f][i]], Pa)
        if fac is None or len(fac[2]) == len(P):
            raise ExactGeometryError(f"float facet {f} has no {n} independent points on it with one inside")
        top = max(map(abs, fac[0]))
        unit = [x / top for x in fac[0]]                                  # int / int: no overflow
        if not max(abs(x / math.hypot(*unit) - y) for x, y in zip(unit, row)) <= IN_ORDER_TOL:
            raise ExactGeometryError(f"float facet {f} ({row}) has no exact counterpart")
        found.append(fac)
    return P, found


def exact_hull_in_order(V, H, h) -> ExactPolytope:
    """Exact facets of ``co(V)``, one per float row ``(H[f], h[f])``, in the rows' order.

    The points within :data:`IN_ORDER_TOL` of a row (floats) *propose* its facet (:func:`_facet_of`,
    nearest first); exact arithmetic decides: every point inside every facet, each through ``n``
    independent points with one strictly inside (:func:`rows_facets`), none missing (1-D: both
    ends; else :func:`_check_closed`). Repeated rows (collinear ring points) give repeated facets.
    Each unit normal must also be its row's to :data:`IN_ORDER_TOL` (that it is the row's facet).

    Parameters
    ----------
    V : QArray or float array, shape (n_v, n)    floats are taken at their exact values
    H : float array, shape (n_f, n)              a float H-rep's normals (any nonzero norm)
    h : float array, shape (n_f,)

    Returns
    -------
    ExactPolytope
        ``co(V)``, with ``H[f]``'s exact facet in row ``f``.

    Raises
    ------
    ExactGeometryError
        When the rows are not exactly ``co(V)``'s facets (e.g. a nearly collinear vertex kept by
        one hull, dropped by the other); :func:`exact_hull` still gives ``co(V)``, in its order.
    """
    V = QArray.coerce(V)
    P, found = rows_facets(V, H, h)
    facets = {tuple(a): (b, tight) for a, b, tight in found}
    if V.shape[1] == 1 and set(facets) != {(1,), (-1,)}:
        raise ExactGeometryError("a 1-D polytope needs both ends")
    if V.shape[1] > 1:
        _check_closed(P, facets)
    return polytope_of_facets(V, [a for a, _, _ in found], [b for _, b, _ in found])


def exact_halfspaces(H: QArray, h: QArray) -> ExactPolytope:
    """The rows ``H x <= h`` as primitive integer rows with rational offsets (the same set).

    Parameters
    ----------
    H : QArray, shape (f, n)     no row zero
    h : QArray, shape (f,)

    Returns
    -------
    ExactPolytope
        With no vertices (``V`` of shape ``(0, n)``): the set may be unbounded.
    """
    rows, offs = [], []
    for r, o in zip(H.num.tolist(), h.to_fractions().tolist()):       # r . x <= o H.den
        k = math.gcd(*r)
        if k == 0:
            raise ExactGeometryError("a zero row is not a half-space")
        rows.append([v // k for v in r])
        offs.append(o * H.den / k)
    Hq = np.array(rows, dtype=object).reshape(len(rows), H.shape[1])
    scale = np.array([max(abs(v) for v in r) for r in rows], dtype=object)
    return ExactPolytope(QArray(np.zeros((0, H.shape[1]), dtype=object), 1), Hq, QArray.from_fractions(offs), scale)


def exact_support(P: ExactPolytope, a) -> QArray:
    """``sigma_P(a_f) = max_k a_f . v_k`` exactly, shape ``(n_f,)`` for ``a`` of shape ``(n_f, n)``."""
    A = QArray.coerce(a)
    vals = A.num @ P.V.num.T                          # (n_f, n_v)
    return QArray(np.array([max(r) for r in vals.tolist()], dtype=object)
                  if vals.shape[0] else np.zeros(0, dtype=object), A.den * P.V.den)
