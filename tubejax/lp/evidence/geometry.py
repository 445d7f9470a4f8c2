"""Exact facets of convex polytopes from rational vertices, and exact support functions.

The float H-reps of :class:`~tubejax.geometry.Polytope` (unit rows) are never used
for a proof. :func:`exact_hull` recomputes the facets of ``co(V)`` from the rational
vertices ``V``:

* 1-D: ``[min V, max V]``;
* 2-D: Andrew's monotone chain with exact integer orientation tests;
* n-D: qhull (float) proposes facet simplices; each one's normal is the exact
  generalised cross product of its edge vectors (integer minors), every vertex is
  checked to lie on the inner side exactly, and the simplices must form a closed
  surface (every ridge in exactly two of them). A nondegenerate closed surface of
  supporting simplices covers the whole boundary of ``co(V)``, so the half-spaces
  cut out exactly ``co(V)`` -- no facet can be missing.

Rows are primitive integer vectors; ``scale`` holds each row's largest absolute
entry, so that violations can be reported per unit (max-norm) row.
"""

from __future__ import annotations

import math
from collections import Counter
from fractions import Fraction
from itertools import combinations
from typing import NamedTuple

import numpy as np

from .rational import QArray, decimal_rational, sqrt_upper

__all__ = ["ExactPolytope", "ExactGeometryError", "exact_hull", "exact_support", "ExactBall",
           "disturbance_support_upper", "exact_disturbance"]


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

    def bbox(self) -> tuple[list, list]:
        """Exact bounding box ``(lo, hi)``: lists of Fractions, length ``n``."""
        F = self.V.to_fractions()
        return [min(F[:, d]) for d in range(self.dim)], [max(F[:, d]) for d in range(self.dim)]


def _primitive(a: list[int]) -> list[int]:
    g = 0
    for v in a:
        g = math.gcd(g, v)
    return [v // g for v in a] if g > 1 else list(a)


def _det(M: list[list[int]]) -> int:
    """Determinant of a square integer matrix (Bareiss, fraction-free)."""
    A = [row[:] for row in M]
    k = len(A)
    if k == 0:
        return 1
    sign, prev = 1, 1
    for i in range(k - 1):
        if A[i][i] == 0:
            for r in range(i + 1, k):
                if A[r][i] != 0:
                    A[i], A[r] = A[r], A[i]
                    sign = -sign
                    break
            else:
                return 0
        for r in range(i + 1, k):
            for c in range(i + 1, k):
                A[r][c] = (A[r][c] * A[i][i] - A[r][i] * A[i][c]) // prev
        prev = A[i][i]
    return sign * A[k - 1][k - 1]


def _finish(V: QArray, rows: list[list[int]], offs: list[int]) -> ExactPolytope:
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
    return _finish(V, [[-1], [1]], [-lo, hi])


def _hull_2d(V: QArray) -> ExactPolytope:
    pts = sorted(set(map(tuple, V.num.tolist())))
    if len(pts) < 3:
        raise ExactGeometryError(f"a 2-D polytope needs 3 points not on a line, got {len(pts)} distinct")

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    ring = lower[:-1] + upper[:-1]                  # counter-clockwise, no collinear points
    if len(ring) < 3:
        raise ExactGeometryError("the points are collinear: no 2-D polytope")
    rows, offs = [], []
    for a, b in zip(ring, ring[1:] + ring[:1]):
        nrm = _primitive([b[1] - a[1], a[0] - b[0]])   # outward for a CCW ring
        rows.append(nrm)
        offs.append(nrm[0] * a[0] + nrm[1] * a[1])
    return _finish(V, rows, offs)


def _hull_nd(V: QArray) -> ExactPolytope:
    from scipy.spatial import ConvexHull

    n = V.shape[1]
    P = V.num.tolist()
    try:
        hull = ConvexHull(V.to_float())
    except Exception as exc:                        # QhullError for flat input
        raise ExactGeometryError(f"qhull could not build the hull in R^{n}: {exc}") from None
    facets, ridges = {}, Counter()
    for simplex in hull.simplices:
        idx = sorted(int(v) for v in simplex)
        p0 = P[idx[0]]
        D = [[P[v][d] - p0[d] for d in range(n)] for v in idx[1:]]      # (n-1, n)
        a = [(-1) ** c * _det([row[:c] + row[c + 1:] for row in D]) for c in range(n)]
        if not any(a):
            raise ExactGeometryError("qhull proposed a degenerate facet simplex")
        a = _primitive(a)
        b = sum(x * y for x, y in zip(a, p0))
        side = [sum(x * y for x, y in zip(a, p)) - b for p in P]
        if max(side) > 0:
            if min(side) < 0:
                raise ExactGeometryError("a facet proposed by qhull does not support the points exactly")
            a, b = [-x for x in a], -b
        facets[tuple(a)] = b
        for r in combinations(idx, n - 1):
            ridges[r] += 1
    if any(c != 2 for c in ridges.values()):
        raise ExactGeometryError("qhull's facets do not close up exactly (a ridge is not shared by two)")
    return _finish(V, [list(a) for a in facets], list(facets.values()))


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


def exact_support(P: ExactPolytope, a) -> QArray:
    """``sigma_P(a_f) = max_k a_f . v_k`` exactly, shape ``(n_f,)`` for ``a`` of shape ``(n_f, n)``."""
    A = QArray.coerce(a)
    vals = A.num @ P.V.num.T                          # (n_f, n_v)
    return QArray(np.array([max(r) for r in vals.tolist()], dtype=object)
                  if vals.shape[0] else np.zeros(0, dtype=object), A.den * P.V.den)


class ExactBall(NamedTuple):
    """``{w : ||w||_2 <= radius}`` with a rational radius."""

    dim: int
    radius: Fraction


def exact_disturbance(W):
    """The rational disturbance set of a :class:`~tubejax.geometry.Ball` or ``Polytope``.

    Ball: radius by :func:`decimal_rational`; polytope: vertices by
    :func:`decimal_rational` (both are typed data, SPEC section 1).
    """
    from ...geometry import Ball

    if isinstance(W, Ball):
        return ExactBall(int(W.dim), decimal_rational(W.radius))
    return exact_hull(QArray.from_decimals(W.vertices))


def disturbance_support_upper(W, a) -> QArray:
    """A rational upper bound of ``sigma_W(a_f)`` per row, shape ``(n_f,)``.

    Polytope ``W``: exact. Ball: ``r ||a_f||_2`` rounded up (:func:`sqrt_upper`), exact
    when the norm is rational.

    Parameters
    ----------
    W : ExactBall or ExactPolytope
    a : QArray or array of Fractions / ints, shape (n_f, n)
    """
    A = QArray.coerce(a)
    if isinstance(W, ExactBall):
        sq = [sum(v * v for v in row) for row in A.num.tolist()]
        vals = [W.radius * sqrt_upper(Fraction(s)) / A.den for s in sq]
        return QArray.from_fractions(np.array(vals, dtype=object)) if vals else \
            QArray(np.zeros(0, dtype=object))
    return exact_support(W, A)
