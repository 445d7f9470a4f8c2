"""Exact facets of a box, and of the hull of two boxes, without the face lattice.

:func:`~tubejax.lp.evidence.exact_geometry.exact_hull_in_order` proves no facet is missing by a
ridge walk, which dominates the exact proof of a 6-D tube. When ``co(V)`` is the hull of one or two
axis-aligned boxes ``[a_lo, a_hi]``, ``[b_lo, b_hi]``, it is
``{x : exists lam in [0, 1], lam a_lo + (1 - lam) b_lo <= x <= lam a_hi + (1 - lam) b_hi}``, and
eliminating ``lam`` (Fourier-Motzkin, exact integers) gives a complete H-representation; every facet
is a row of it. :func:`boxes_hull_in_order` checks exactly that every point of ``V`` is a box corner
and every hull vertex a point of ``V``, that each float row is one of these facets (its unit normal and
offset the row's to :data:`~tubejax.lp.evidence.exact_geometry.IN_ORDER_TOL`, as
:func:`~tubejax.lp.evidence.exact_geometry.rows_facets` compares them, and no other facet's), and that
the rows have all the facets. Its answer is then ``exact_hull_in_order``'s; ``None`` means "not shown
this way". No float decides: the facets, and that they are all, come from the exact elimination; the
floats only say which row is which facet.
"""

from __future__ import annotations

import functools
import math
from fractions import Fraction
from itertools import product

import flint
import numpy as np

from .exact_geometry import IN_ORDER_TOL, ExactGeometryError, ExactPolytope, polytope_of_facets
from .rational import QArray, int_products

__all__ = ["exact_box", "boxes_hull_facets", "boxes_hull_in_order", "HULL_CACHE_SIZE"]

#: Hulls of two boxes kept, by the boxes' shape and relative place (a joint phase meets the same ones often).
HULL_CACHE_SIZE = 2048


def exact_box(V) -> tuple[list, list]:
    """The exact bounding box of points ``V`` (QArray or floats at their exact values, shape
    ``(n_v, n)``): ``(lo, hi)``, lists of ``n`` Fractions."""
    V = QArray.coerce(V)
    cols = V.num.T.tolist()
    return [Fraction(min(c), V.den) for c in cols], [Fraction(max(c), V.den) for c in cols]


def _lcm_den(values) -> int:
    return math.lcm(*(Fraction(v).denominator for v in values))


def _lam_rows(boxes: list, D: int) -> list:
    """The rows ``(g, c, e)``: ``g . y + c lam <= e`` (integers; ``y = D x``) of the boxes'
    ``lam``-combination (one box: the same box twice) and ``0 <= lam <= 1``."""
    (alo, ahi), (blo, bhi) = boxes[0], boxes[-1]
    n, rows = len(alo), [([0] * len(alo), -1, 0), ([0] * len(alo), 1, 1)]
    for k in range(n):
        al, ah, bl, bh = (int(v * D) for v in (alo[k], ahi[k], blo[k], bhi[k]))
        unit = [int(d == k) for d in range(n)]
        rows.append(([-u for u in unit], al - bl, -bl))         # y_k >= bl + lam (al - bl)
        rows.append((unit, bh - ah, bh))                          # y_k <= bh + lam (ah - bh)
    return rows


def _eliminated(rows: list) -> list:
    """Fourier-Motzkin: the rows ``(g, e)``, ``g . y <= e``, without ``lam`` (same projection)."""
    out = [(g, e) for g, c, e in rows if c == 0]
    pos, neg = [r for r in rows if r[1] > 0], [r for r in rows if r[1] < 0]
    for gp, cp, ep in pos:
        for gq, cq, eq in neg:
            out.append(([-cq * x + cp * y for x, y in zip(gp, gq)], -cq * ep + cp * eq))
    return out


def boxes_hull_facets(boxes: list):
    """The facets of the hull of one or two boxes (see the module doc), exactly.

    Parameters
    ----------
    boxes : list of (lo, hi)
        One or two boxes, each two sequences of ``n >= 2`` rationals (Fractions, ints or floats
        at their exact values), ``lo <= hi``.

    Returns
    -------
    (dict, list) or None
        ``{(primitive integer normal): offset (Fraction)}`` of every facet, and the corners
        (tuples of Fractions) that are vertices of the hull; ``None`` when the hull is not
        full-dimensional.

    Raises
    ------
    ExactGeometryError
        When some ``lo > hi``.
    """
    hull = _hull_of_boxes(boxes)
    if hull is None:
        return None
    facets, corners, is_vertex, D = hull
    return ({a: Fraction(e, D) for a, e in facets.items()},
            [tuple(Fraction(v, D) for v in p) for p, keep in zip(corners.tolist(), is_vertex) if keep])


def _hull_of_boxes(boxes: list):
    """:func:`boxes_hull_facets` in integers: ``(facets, corners, is_vertex, D)``, the facets as
    ``{normal: offset}`` of ``normal . y <= offset`` with ``y = D x``, the distinct corners ``D x`` (object
    array ``(k, n)``, sorted) and which of them are vertices of the hull (bool ``(k,)``); ``None``
    when the hull is not full-dimensional.

    The boxes moved by ``-t`` (``t`` the first box's ``lo``) are solved once per shape
    (:func:`_hull_at_origin`, cached) and moved back exactly: translating keeps the facets' normals and
    the corners' order, and adds ``a . t`` to the offset of normal ``a``.
    """
    boxes = [([Fraction(v) for v in lo], [Fraction(v) for v in hi]) for lo, hi in boxes]
    if any(a > b for lo, hi in boxes for a, b in zip(lo, hi)):
        raise ExactGeometryError("a box needs lo <= hi")
    t = boxes[0][0]
    rel = tuple((tuple(v - s for v, s in zip(lo, t)), tuple(v - s for v, s in zip(hi, t))) for lo, hi in boxes)
    at_origin = _hull_at_origin(rel)
    if at_origin is None:
        return None
    facets_r, corners_r, is_vertex, D_r = at_origin
    D = _lcm_den([v for lo, hi in boxes for v in lo + hi])         # a multiple of D_r (rel's denominators divide it)
    m = D // D_r
    Dt = np.array([int(v * D) for v in t], dtype=object)
    corners = corners_r * m + Dt[None, :]
    facets = {a: off * m + sum(x * y for x, y in zip(a, Dt)) for a, off in facets_r.items()}
    return facets, corners, list(is_vertex), D


@functools.lru_cache(maxsize=HULL_CACHE_SIZE)
def _hull_at_origin(boxes: tuple):
    """:func:`_hull_of_boxes` of boxes given as Fractions (a tuple of ``(lo, hi)`` tuples), by Fourier-Motzkin
    elimination (module doc); cached: the result is not to be changed."""
    n = len(boxes[0][0])
    D = _lcm_den([v for lo, hi in boxes for v in lo + hi])
    scaled = [([int(v * D) for v in lo], [int(v * D) for v in hi]) for lo, hi in boxes]
    corners = sorted({c for lo, hi in scaled for c in product(*zip(lo, hi))})
    rows = [(g, e) for g, e in _eliminated(_lam_rows(list(boxes), D)) if any(g)]    # a zero row: 0 <= e, no constraint
    C = np.array(corners, dtype=object).reshape(len(corners), n)
    side = int_products([g for g, _ in rows], C) - np.array([e for _, e in rows], dtype=object)[:, None]
    if side.size and side.max() > 0:
        raise ExactGeometryError("an eliminated row cuts a corner: the elimination is wrong")
    facets, tight_of = {}, {}
    for (g, e), on in zip(rows, (side == 0).tolist()):
        k, tight = math.gcd(*g), [i for i, v in enumerate(on) if v]
        a = tuple(v // k for v in g)
        if a not in tight_of and tight and len(tight) < len(corners) and _affine_rank(C, tight) == n - 1:
            facets[a], tight_of[a] = Fraction(e, k), tight
    if not facets:
        return None
    rows_at = [[] for _ in corners]                                # the facets each corner is on
    for a, tight in tight_of.items():
        for i in tight:
            rows_at[i].append(list(a))
    is_vertex = [len(at) >= n and flint.fmpz_mat(at).rank() == n for at in rows_at]
    return facets, C, is_vertex, D


def _affine_rank(C: np.ndarray, idx: list) -> int:
    """The dimension of the affine hull of the integer points ``C[idx]`` (object array ``(k, n)``), exactly (FLINT)."""
    return flint.fmpz_mat((C[idx[1:]] - C[idx[0]]).tolist()).rank() if len(idx) > 1 else 0


def boxes_hull_in_order(V, H, h, boxes: list) -> ExactPolytope | None:
    """:func:`~tubejax.lp.evidence.exact_geometry.exact_hull_in_order` ``(V, H, h)`` when ``co(V)``
    is the hull of ``boxes`` (see the module doc), else ``None``.

    Parameters
    ----------
    V : QArray or float array, shape (n_v, n)    floats are taken at their exact values
    H : float array, shape (n_f, n)              a float H-rep's normals (any nonzero norm)
    h : float array, shape (n_f,)
    boxes : list of (lo, hi)                     one or two boxes (:func:`boxes_hull_facets`)

    Returns
    -------
    ExactPolytope or None
        ``co(V)``, with ``H[f]``'s exact facet in row ``f``; ``None`` when ``co(V)`` is not shown
        to be the boxes' hull, or the rows are not exactly its facets.
    """
    V = QArray.coerce(V)
    if V.num.ndim != 2 or V.shape[1] < 2 or not 1 <= len(boxes) <= 2 \
            or any(len(b) != V.shape[1] for box in boxes for b in box):
        return None
    try:
        hull = _hull_of_boxes(boxes)
    except ExactGeometryError:
        return None
    if hull is None:
        return None
    facets, corners, is_vertex, D = hull
    Q = math.lcm(V.den, D)                                         # points and corners in units of 1 / Q
    points = set(map(tuple, (V.num * (Q // V.den)).tolist()))
    at_corners = set(map(tuple, (corners * (Q // D)).tolist()))    # every corner of a box is one of them
    vertices = {p for p, keep in zip(map(tuple, (corners * (Q // D)).tolist()), is_vertex) if keep}
    if not vertices <= points or not points <= at_corners:
        return None                                               # co(V) is not the boxes' hull
    rows = _rows_of_facets(V, H, h, {a: e / D for a, e in facets.items()})
    if rows is None:
        return None
    return polytope_of_facets(V, [list(a) for a, _ in rows], [b for _, b in rows])


def _rows_of_facets(V: QArray, H, h, facets: dict) -> list | None:
    """Each float row's facet among ``facets`` (``{primitive normal: offset}``, ``normal . x <= offset``, every
    facet of ``co(V)``): ``[(normal, offset in numerator units of V), ...]`` in the rows' order, or ``None``.

    A row's facet is the one whose unit normal is the row's to :data:`~.exact_geometry.IN_ORDER_TOL` (the
    comparison :func:`~.exact_geometry.rows_facets` makes) and whose offset per unit normal is the row's to
    its tolerance; there must be exactly one, and every facet must be some row's. The normals are the
    exact ones, so the answer is :func:`~.exact_geometry.rows_facets`' without its proposals from the points
    near each row (an exact null space per row)."""
    H, h = np.asarray(H, dtype=float), np.asarray(h, dtype=float)
    n = V.shape[1]
    if H.ndim != 2 or h.ndim != 1 or not h.size or H.shape != (h.size, n):
        return None
    nrm = np.sqrt(np.einsum("ij,ij->i", H, H))
    if not (np.all((nrm > 0) & (nrm < np.inf)) and np.isfinite(h).all()):
        return None
    Hu, hu = H / nrm[:, None], h / nrm
    normals = list(facets)
    units = []
    for a in normals:
        top = max(map(abs, a))
        unit = [x / top for x in a]                                       # int / int: no overflow
        hyp = math.hypot(*unit)
        units.append([x / hyp for x in unit])
    U = np.array(units, dtype=float)                                      # (k, n)
    offs = np.array([float(facets[a]) for a in normals]) / np.array([math.hypot(*a) for a in normals], dtype=float)
    Pf = np.array([[x / V.den for x in p] for p in V.num.tolist()], dtype=float)    # int / int: rounded once
    if not (np.all(np.isfinite(Pf)) and np.all(np.isfinite(offs))):
        return None
    tol = IN_ORDER_TOL * float(np.max(np.ptp(Pf, axis=0))) + 64 * np.finfo(float).eps * float(np.max(np.abs(Pf)))
    match = (np.max(np.abs(Hu[:, None, :] - U[None, :, :]), axis=2) <= IN_ORDER_TOL) \
        & (np.abs(hu[:, None] - offs[None, :]) <= tol)                 # (n_f, k)
    if not np.all(match.sum(axis=1) == 1):
        return None
    which = np.argmax(match, axis=1)
    if np.unique(which).size != len(normals):
        return None                                                       # a facet no row has
    out = []
    for k in which.tolist():
        b = facets[normals[k]] * V.den                                    # through vertices of V: an integer
        if b.denominator != 1:
            return None
        out.append((normals[k], int(b)))
    return out
