"""Convex polytopes held in both vertex (V) and half-space (H) representation.

A :class:`Polytope` stores ``vertices (n_v, n)`` in canonical order (:func:`canonical_vertex_order`)
and ``H (n_f, n), h (n_f,)`` with unit-norm rows (``h``: each facet's signed distance from the
origin). Conversions use :mod:`scipy.spatial` (``ConvexHull``, ``HalfspaceIntersection``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, HalfspaceIntersection

from ...errors import GeometryError

__all__ = [
    "Polytope",
    "canonical_vertex_order",
    "chebyshev_ball",
    "convex_hull_of",
    "first_distinct_rows",
    "vertices_from_hrep",
]

_DEDUP_DECIMALS = 10
#: Relative size (to the ring's extent) at or below which two ring points coincide,
#: and (to the extent squared) at or below which a polygon has no area.
_RING_TOL = 1e-12


def _points(vertices, what: str = "vertices") -> np.ndarray:
    """``vertices`` as a finite float array of shape ``(k, n)``, ``k, n >= 1``."""
    try:
        V = np.asarray(vertices, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise GeometryError(f"{what} must be an array of numbers of shape (n_v, n), got {vertices!r}") from None
    if V.ndim != 2 or V.shape[0] == 0 or V.shape[1] == 0:
        raise GeometryError(f"{what} must be a non-empty array of shape (n_v, n), got shape {V.shape}")
    if not np.all(np.isfinite(V)):
        raise GeometryError(f"{what} must be finite, got {V.tolist()}")
    return V


def canonical_vertex_order(vertices: np.ndarray) -> np.ndarray:
    """``vertices (n_v, n)`` in the project's deterministic order, which fixes the pairing
    ``z_k <-> v_{i,k}`` (docs/math/tube-lp.md#vertex-pairing): in 2-D counter-clockwise from the
    bottom-left vertex (smallest ``y``, then smallest ``x``); otherwise lexicographic, the last
    coordinate most significant (a box's corners in binary counting order).
    """
    V = _points(vertices)
    n = V.shape[1]
    if n == 2 and V.shape[0] >= 3:
        c = V.mean(axis=0)
        ang = np.arctan2(V[:, 1] - c[1], V[:, 0] - c[0])
        ccw = V[np.argsort(ang, kind="stable")]
        start = np.lexsort((np.round(ccw[:, 0], 12), np.round(ccw[:, 1], 12)))[0]
        return np.roll(ccw, -start, axis=0)
    keys = tuple(np.round(V[:, d], 12) for d in range(n))  # lexsort: last key most significant
    return V[np.lexsort(keys)]


def first_distinct_rows(A: np.ndarray) -> np.ndarray:
    """The rows of ``A (R, c)`` that no earlier row equals when both are rounded to
    :data:`_DEDUP_DECIMALS` decimals, in order, shape ``(k,)``: the first of each row of
    ``np.unique(..., axis=0)`` (``k`` its count), found by the rounded rows' bytes (``-0.0`` made
    ``0.0``, which ``np.unique`` finds equal) instead of its sort of rows; with a non-finite entry, by
    ``np.unique`` itself."""
    key = np.round(A, _DEDUP_DECIMALS)
    if not np.all(np.isfinite(key)):
        _, idx = np.unique(key, axis=0, return_index=True)
        return np.sort(idx)
    key = np.ascontiguousarray(key + 0.0)
    _, idx = np.unique(key.view(np.dtype((np.void, key.shape[1] * key.itemsize))).ravel(), return_index=True)
    return np.sort(idx)


def _unique_rows(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    idx = first_distinct_rows(np.hstack([A, b[:, None]]))
    return A[idx], b[idx]


def _hrep(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit-normalised ``H (n_f, n), h (n_f,)`` and the extreme points ``(n_v, n)`` (canonical order)
    of ``co(vertices)``, ``vertices (N, n)``; a ``GeometryError`` when they do not span ``R^n``."""
    V = _points(vertices)
    n = V.shape[1]
    if n == 1:
        lo, hi = V.min(), V.max()
        if not hi > lo:
            raise GeometryError(f"a 1-D polytope needs two distinct points, got {V.ravel().tolist()}")
        return np.array([[-1.0], [1.0]]), np.array([-lo, hi]), np.array([[lo], [hi]])
    if V.shape[0] <= n:
        raise GeometryError(f"{V.shape[0]} points cannot span R^{n} (a polytope with volume needs at least "
                            f"{n + 1}), got {V.tolist()}")
    try:
        hull = ConvexHull(V)
    except Exception:  # scipy's QhullError: flat or degenerate input; its text is qhull's manual
        raise GeometryError(f"the {V.shape[0]} points do not span R^{n}: their hull has no volume "
                            f"(they lie in a lower-dimensional plane), got {_short_points(V)}") from None
    if n == 2:  # qhull gives the 2-D hull's vertices counter-clockwise
        return _hrep_ccw_polygon(V[hull.vertices])
    eq = hull.equations  # a.x + b <= 0 with unit a
    H, h = _unique_rows(eq[:, :n], -eq[:, n])
    return H, h, canonical_vertex_order(V[hull.vertices])


def _short_points(V: np.ndarray, limit: int = 6) -> str:
    rows = [[float(f"{x:.6g}") for x in row] for row in V[:limit].tolist()]
    return str(rows)[:-1] + (", ...]" if len(V) > limit else "]")


def _hrep_ccw_polygon(ext: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H-rep of a convex polygon given by its extreme points counter-clockwise, shape ``(k, 2)``."""
    start = np.lexsort((np.round(ext[:, 0], 12), np.round(ext[:, 1], 12)))[0]
    ext = np.roll(ext, -start, axis=0)              # canonical order: CCW from the bottom-left
    e = np.roll(ext, -1, axis=0) - ext
    H = np.stack([e[:, 1], -e[:, 0]], axis=1)
    H /= np.linalg.norm(H, axis=1, keepdims=True)
    return H, np.einsum("ij,ij->i", H, ext), ext


def chebyshev_ball(H: np.ndarray, h: np.ndarray, cap: float | None = None) -> tuple[np.ndarray, float]:
    """Centre ``(n,)`` and radius of the largest ball in ``{x : H x <= h}``, ``H (n_f, n)``, the radius at
    most ``cap`` (negative: how far the set is from having one; ``inf``: unbounded; ``-inf``: the LP failed)."""
    norms = np.linalg.norm(H, axis=1)
    n = H.shape[1]
    c = np.zeros(n + 1)
    c[-1] = -1.0
    res = linprog(c, A_ub=np.hstack([H, norms[:, None]]), b_ub=h,
                  bounds=[(None, None)] * n + [(None, cap)], method="highs")
    if res.status == 3:
        return np.zeros(n), np.inf
    if res.status != 0:
        return np.zeros(n), -np.inf
    return res.x[:n], float(res.x[-1])


def vertices_from_hrep(H: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Vertices ``(n_v, n)`` (canonical order) of the bounded polytope ``{x : H x <= h}``,
    ``H (n_f, n)``, ``h (n_f,)``; a ``GeometryError`` for non-finite data or a set that is empty,
    has no interior, or is unbounded."""
    H = np.asarray(H, float)
    h = np.asarray(h, float)
    if H.ndim != 2 or h.shape != (H.shape[0],) or H.shape[0] == 0:
        raise GeometryError(f"an H-representation needs H of shape (n_f, n) and h of shape (n_f,), "
                            f"got {H.shape} and {h.shape}")
    if not (np.all(np.isfinite(H)) and np.all(np.isfinite(h))):
        raise GeometryError("an H-representation must be finite (H and h hold NaN or infinity)")
    center, radius = chebyshev_ball(H, h)
    if not np.isfinite(radius):
        raise GeometryError("the H-representation is unbounded" if radius > 0 else "the H-representation is empty")
    if radius < -1e-12:
        raise GeometryError("the H-representation is empty")
    if radius <= 1e-12:
        raise GeometryError("the H-representation has no interior")
    n = H.shape[1]
    if n == 1:
        lo = max((h[k] / H[k, 0] for k in range(len(h)) if H[k, 0] < 0), default=-np.inf)
        hi = min((h[k] / H[k, 0] for k in range(len(h)) if H[k, 0] > 0), default=np.inf)
        if not (np.isfinite(lo) and np.isfinite(hi)):
            raise GeometryError("the H-representation is unbounded")
        return np.array([[lo], [hi]])
    hs = HalfspaceIntersection(np.hstack([H, -h[:, None]]), center)
    pts = hs.intersections
    if not np.all(np.isfinite(pts)):
        raise GeometryError("the H-representation is unbounded")
    _, _, ext = _hrep(pts)
    return ext


@dataclass(frozen=True, eq=False)
class Polytope:
    """A bounded, full-dimensional convex polytope ``{x : H x <= h} = co(vertices)``.

    Attributes
    ----------
    vertices : ndarray, shape (n_v, n)
        Extreme points in canonical order (:func:`canonical_vertex_order`).
    H : ndarray, shape (n_f, n)
        Facet normals, unit 2-norm.
    h : ndarray, shape (n_f,)
        Facet offsets.
    """

    vertices: np.ndarray
    H: np.ndarray
    h: np.ndarray

    @classmethod
    def from_vertices(cls, vertices) -> "Polytope":
        """Build from points ``(k, n)``, redundant ones dropped; a ``GeometryError`` for non-finite
        points or a hull without volume in ``R^n``."""
        H, h, ext = _hrep(_points(vertices))
        return cls(ext, H, h)

    @classmethod
    def from_convex_polygon(cls, ring) -> "Polytope":
        """A 2-D polytope from the ring of a convex polygon, without qhull.

        Parameters
        ----------
        ring : array_like, shape (k, 2)
            The polygon's vertices in either orientation; a closing repeat of the first
            point is dropped. Collinear points on an edge are allowed (their facets repeat).

        Raises
        ------
        GeometryError
            Fewer than 3 points, non-finite points, two consecutive points that coincide
            (within ``1e-12`` of the ring's extent), a ring without area (collinear points),
            or a ring that turns the wrong way somewhere (not convex).
        """
        V = _points(ring, "a convex polygon's ring")
        if len(V) > 1 and np.array_equal(V[0], V[-1]):
            V = V[:-1]
        if V.shape[1] != 2 or len(V) < 3:
            raise GeometryError(f"a convex polygon needs >= 3 points in 2-D, got shape {V.shape}")
        extent = float(np.max(V.max(axis=0) - V.min(axis=0)))
        e = np.roll(V, -1, axis=0) - V
        length = np.hypot(e[:, 0], e[:, 1])
        if np.any(length <= _RING_TOL * extent):
            k = int(np.argmax(length <= _RING_TOL * extent))
            raise GeometryError(f"a convex polygon's ring repeats a vertex: points {k} and {(k + 1) % len(V)} "
                                f"coincide at {V[k].tolist()}")
        area2 = float(np.sum(V[:, 0] * np.roll(V[:, 1], -1) - np.roll(V[:, 0], -1) * V[:, 1]))
        if abs(area2) <= 2 * _RING_TOL * extent ** 2:
            raise GeometryError(f"a convex polygon's ring has no area (its points are collinear): "
                                f"{_short_points(V)}")
        if area2 < 0:
            V = V[::-1]
            e = np.roll(V, -1, axis=0) - V
            length = np.hypot(e[:, 0], e[:, 1])
        turn = e[:, 0] * np.roll(e[:, 1], -1) - e[:, 1] * np.roll(e[:, 0], -1)   # at vertex k + 1
        if np.any(turn < -_RING_TOL * length * np.roll(length, -1)):
            raise GeometryError(f"the ring is not convex (it turns clockwise at a vertex of a counter-"
                                f"clockwise ring): {_short_points(V)}")
        H, h, ext = _hrep_ccw_polygon(V)
        return cls(ext, H, h)

    @classmethod
    def from_hrep(cls, H, h) -> "Polytope":
        """Build from ``H x <= h`` (rows need not be normalised; redundant rows are dropped)."""
        V = vertices_from_hrep(H, h)
        return cls.from_vertices(V)

    @classmethod
    def box(cls, lower, upper) -> "Polytope":
        """The axis-aligned box ``[lower, upper]``, any dimension."""
        lo = np.atleast_1d(np.asarray(lower, float))
        hi = np.atleast_1d(np.asarray(upper, float))
        if lo.ndim != 1 or lo.shape != hi.shape or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) \
                or np.any(hi <= lo):
            raise GeometryError(f"a box needs finite lower < upper elementwise, got {lo.tolist()} and {hi.tolist()}")
        n = lo.size
        corners = np.array(np.meshgrid(*[[lo[d], hi[d]] for d in range(n)], indexing="ij"))
        V = corners.reshape(n, -1).T
        H = np.vstack([-np.eye(n), np.eye(n)])
        h = np.concatenate([-lo, hi])
        return cls(canonical_vertex_order(V), H, h)

    dim = property(lambda self: int(self.vertices.shape[1]), doc="Ambient dimension ``n``.")

    n_vertices = property(lambda self: int(self.vertices.shape[0]))

    @property
    def centroid(self) -> np.ndarray:
        """Mean of the vertices, shape ``(n,)``."""
        return self.vertices.mean(axis=0)

    def contains(self, x, tol: float = 1e-9) -> np.ndarray:
        """Whether points ``x (..., n)`` lie in the polytope up to ``tol``, bool ``(...)``."""
        return self.violation(x) <= tol

    def violation(self, x) -> np.ndarray:
        """Largest ``H x - h`` (positive outside), shape ``(...)`` for ``x`` of shape ``(..., n)``."""
        x = np.asarray(x, float)
        return np.max(x @ self.H.T - self.h, axis=-1)

    def support(self, a) -> np.ndarray:
        """Support function ``max_{v in P} a.v`` for directions ``a`` of shape (..., n)."""
        return np.max(np.asarray(a, float) @ self.vertices.T, axis=-1)

    def bounding_box(self) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)``, each of shape ``(n,)`` (computed once, read-only)."""
        return self._bbox

    @cached_property
    def is_box(self) -> bool:
        """Whether this is an axis-aligned box, decided exactly: ``2 n`` facets with one nonzero coordinate
        each (no tolerance: a box tilted by rounding is not one) and ``2^n`` vertices."""
        return (self.n_vertices == 2 ** self.dim and self.H.shape[0] == 2 * self.dim
                and bool(np.all(np.count_nonzero(self.H, axis=1) == 1)))

    @cached_property
    def row_norms(self) -> np.ndarray:
        """The 2-norms of the rows of ``H``, shape ``(n_f,)`` (1 up to rounding; read-only)."""
        nrm = np.sqrt(np.einsum("fi,fi->f", self.H, self.H))
        nrm.setflags(write=False)
        return nrm

    @cached_property
    def _bbox(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        lo.setflags(write=False)
        hi.setflags(write=False)
        return lo, hi

    def __repr__(self) -> str:
        return f"Polytope(n={self.dim}, n_vertices={self.n_vertices}, n_facets={self.H.shape[0]})"

    def __getstate__(self) -> dict:
        # the three fields only: values cached on the instance (is_box, row_norms, _bbox) are recomputed
        # where needed, so a pickle (problems sent to HiGHS helper processes) carries half the arrays
        return {"vertices": self.vertices, "H": self.H, "h": self.h}


def convex_hull_of(*polytopes: Polytope) -> Polytope:
    """``co(P_1 u P_2 u ...)``, e.g. ``P_ij = co(P_i u P_j)``."""
    return Polytope.from_vertices(np.vstack([p.vertices for p in polytopes]))
