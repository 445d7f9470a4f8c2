"""The hull of two axis-aligned boxes, in floats, without qhull (docs/math/problem-data.md).

``co(A u B)`` for boxes ``A = [a_lo, a_hi]``, ``B = [b_lo, b_hi]`` is the set of ``x`` with some
``lam in [0, 1]``, ``lam a_lo + (1 - lam) b_lo <= x <= lam a_hi + (1 - lam) b_hi``. Eliminating ``lam``
(Fourier-Motzkin) gives a complete H-representation: the bounding box's rows, and one row in two
coordinates ``(x_k, x_m)`` for each lower bound on ``lam`` from axis ``k`` and upper bound from axis
``m``. Every facet is one of these; a candidate is a facet when the points on its supporting hyperplane
span ``n - 1`` affine dimensions, a point a vertex when the facets through it span ``n`` (both by
``numpy``'s rank). qhull triangulates thousands of facets of a 6-D pair hull for a few dozen; below
:data:`FROM_DIM` dimensions it is the faster, and gets the hull (docs/explanation/performance.md,
Box-pair hulls). :mod:`~tubejax.lp.evidence.exact_boxes` proves the same facets exactly when a tube's proof needs
them; floats here only build the LP.
"""

from __future__ import annotations

import numpy as np

from .polytope import first_distinct_rows

__all__ = ["box_pair_hull"]

#: Points within this fraction of the points' extent of a supporting hyperplane lie on it.
_ON_FACET_TOL = 1e-9
#: The least dimension where the elimination is used: below it qhull is faster.
FROM_DIM = 5


def _box_of(points: np.ndarray):
    """``(lo, hi)`` of ``points (2**n, n)`` when they are the corners of a full-dimensional box, else ``None``."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    if not np.all(lo < hi) or not np.all((points == lo) | (points == hi)):
        return None
    bits = (points == hi).astype(np.int64) @ (1 << np.arange(points.shape[1], dtype=np.int64))
    return (lo, hi) if np.unique(bits).size == points.shape[0] else None


def _lam_rows(a: tuple, b: tuple) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rows ``g . x + c lam <= e`` of the ``lam``-combination per axis, lower side then upper side:
    axes ``(2n,)``, signs ``(2n,)`` (``g = sign * e_axis``) and ``c (2n,)``."""
    (alo, ahi), (blo, bhi) = a, b
    n = len(alo)
    axes = np.concatenate([np.arange(n), np.arange(n)])
    signs = np.concatenate([-np.ones(n), np.ones(n)])
    c = np.concatenate([alo - blo, bhi - ahi])       # x_k >= b_lo + lam (a_lo - b_lo); x_k <= b_hi + lam (a_hi - b_hi)
    return axes, signs, c


def _candidates(a: tuple, b: tuple, n: int) -> np.ndarray:
    """Candidate facet normals, unit, shape ``(f, n)``: the bounding box's ``2n`` rows, then every
    two-axis row of the elimination of ``lam``."""
    axes, signs, c = _lam_rows(a, b)
    up, down = np.flatnonzero(c > 0), np.flatnonzero(c < 0)          # bounds lam above / below
    p, q = np.repeat(up, down.size), np.tile(down, up.size)
    keep = axes[p] != axes[q]
    p, q = p[keep], q[keep]
    N = np.zeros((p.size, n))
    N[np.arange(p.size), axes[p]] += -c[q] * signs[p]
    N[np.arange(p.size), axes[q]] += c[p] * signs[q]
    eye = np.eye(n)
    N = np.concatenate([-eye, eye, N])
    return N / np.linalg.norm(N, axis=1, keepdims=True)


def _affine_ranks(points: np.ndarray, on: np.ndarray) -> np.ndarray:
    """The affine rank of the points ``on[f]`` (a mask over ``points (P, n)``) for each row, shape ``(f,)``."""
    first = np.argmax(on, axis=1)
    rel = points[None, :, :] - points[first][:, None, :]               # (f, P, n)
    return np.linalg.matrix_rank(np.where(on[:, :, None], rel, 0.0))


def box_pair_hull(points: np.ndarray, from_dim: int = FROM_DIM):
    """Vertices and facets of ``co(points)`` when ``points (2 * 2**n, n)`` are two boxes' corners stacked
    and ``n >= max(2, from_dim)``, else ``None``.

    Returns
    -------
    (idx, H) or None
        ``idx``: the indices of the hull's vertices in ``points`` (the first of coincident points), shape
        ``(n_v,)``; ``H``: unit outer normals of its facets, no two equal, shape ``(f, n)``.
    """
    n_p, n = points.shape
    if n < max(2, from_dim) or n_p != 2 << n:
        return None
    a, b = _box_of(points[:n_p // 2]), _box_of(points[n_p // 2:])
    if a is None or b is None:
        return None
    N = _candidates(a, b, n)
    s = points @ N.T                                                     # (P, f)
    tol = _ON_FACET_TOL * max(float(np.max(np.abs(points - points[0]))), 1e-300)
    on = (s >= s.max(axis=0) - tol).T                                    # (f, P)
    facet = _affine_ranks(points, on) == n - 1
    facet &= np.isin(np.arange(len(N)), first_distinct_rows(N))          # the same normal twice: once
    H, on = N[facet], on[facet]
    spans = np.linalg.matrix_rank(np.where(on.T[:, :, None], H[None, :, :], 0.0)) == n      # (P,)
    _, first_point = np.unique(points, axis=0, return_index=True)
    idx = np.intersect1d(np.flatnonzero(spans), first_point)
    return idx, H
