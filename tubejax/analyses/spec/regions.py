"""Labelled regions as convex pieces: where a proposition ``l<label>`` holds (docs/howto/formulas.md#a-formula).

``l<label>`` holds on the *closed region* of that label: on an n-D box grid the label boxes the user
named, exactly; otherwise the cells carrying the label. The planners test "can meet" against the
pieces and "surely in" by containment in a *cover piece* (:func:`cover_pieces`, the maximal boxes of
a label's box pieces; why this is sound: docs/math/control.md#ltl-over-infinite-runs), so a box that
cuts through cells is neither rounded away nor rounded up.
"""

from __future__ import annotations

import numpy as np

from ...model.geometry import Polytope
from ...model.workspace.boxgrid import LABEL_REGIONS

__all__ = ["region_pieces", "cover_pieces", "maximal_boxes", "inside_mask", "INSIDE_TOL", "MAX_BOX_TABLE"]

#: A cell whose vertices are within this (unit-row) violation of a piece lies inside it
#: (the box grid's own tolerance for grid lines that are meant to coincide).
INSIDE_TOL = 1e-9
#: Largest table of candidate boxes (``prod d_k^2`` for ``d_k`` intervals per axis) enumerated
#: exactly; beyond it every covered elementary box grows greedily into a maximal box.
MAX_BOX_TABLE = 1 << 20


def region_pieces(decomp, labels) -> list:
    """``[(bit, Polytope), ...]``: the convex pieces of the regions of ``labels`` (module docstring).

    Parameters
    ----------
    decomp : CellDecomposition
    labels : sequence of str
        Region label of each proposition bit.

    Returns
    -------
    list of (int, Polytope)
        Bit of the label and one closed convex piece of its region; a label whose
        region has several pieces appears several times.
    """
    bit = {str(l): b for b, l in enumerate(labels)}
    regions = decomp._cache.get(LABEL_REGIONS)
    if regions is not None:
        return [(bit[str(l)], P) for l, pieces in regions.items() if str(l) in bit for P in pieces]
    return [(bit[str(l)], decomp.cells[c]) for c, l in enumerate(decomp.labels)
            if l is not None and str(l) in bit]


def _box_bounds(P):
    """``(lo, hi)`` of ``P`` if it is an axis-aligned box (:attr:`Polytope.is_box`), else ``None``."""
    if not P.is_box:
        return None
    V = np.asarray(P.vertices, float)
    return V.min(0), V.max(0)


def _covered_table(occ: np.ndarray) -> np.ndarray:
    """``cov[a_1, b_1, ..., a_n, b_n]``: every elementary box of ``occ[a_1..b_1, ...]`` is covered."""
    n = occ.ndim
    sat = np.zeros(tuple(d + 1 for d in occ.shape), np.int64)
    sat[(slice(1, None),) * n] = occ.astype(np.int64)
    for k in range(n):
        sat = np.cumsum(sat, axis=k)
    grids = np.meshgrid(*[np.arange(d) for d in occ.shape for _ in (0, 1)], indexing="ij")
    a, b = grids[0::2], grids[1::2]
    total = np.zeros(grids[0].shape, np.int64)
    for corner in range(1 << n):
        idx = tuple(b[k] + 1 if corner >> k & 1 else a[k] for k in range(n))
        total += (-1) ** (n - bin(corner).count("1")) * sat[idx]
    vol = np.ones(grids[0].shape, np.int64)
    for k in range(n):
        vol *= np.maximum(b[k] - a[k] + 1, 0)
    ok = np.ones(grids[0].shape, bool)
    for k in range(n):
        ok &= a[k] <= b[k]
    return ok & (total == vol)


def _maximal_exact(occ: np.ndarray) -> list:
    cov = _covered_table(occ)
    n = occ.ndim
    maximal = cov.copy()
    for k in range(n):
        for axis, step in ((2 * k, -1), (2 * k + 1, 1)):      # a_k - 1, b_k + 1
            grown = np.zeros_like(cov)
            src = [slice(None)] * cov.ndim
            dst = [slice(None)] * cov.ndim
            if step < 0:
                dst[axis], src[axis] = slice(1, None), slice(None, -1)
            else:
                dst[axis], src[axis] = slice(None, -1), slice(1, None)
            grown[tuple(dst)] = cov[tuple(src)]
            maximal &= ~grown
    return [tuple((int(r[2 * k]), int(r[2 * k + 1])) for k in range(n)) for r in np.argwhere(maximal)]


def _maximal_greedy(occ: np.ndarray) -> list:
    n = occ.ndim
    out = set()
    for seed in np.argwhere(occ):
        box = [[int(i), int(i)] for i in seed]
        grew = True
        while grew:
            grew = False
            for k in range(n):
                for end, step in ((1, 1), (0, -1)):
                    nxt = box[k][end] + step
                    if not 0 <= nxt < occ.shape[k]:
                        continue
                    sl = tuple(slice(lo, hi + 1) if j != k else slice(nxt, nxt + 1) for j, (lo, hi) in enumerate(box))
                    if occ[sl].all():
                        box[k][end] = nxt
                        grew = True
        out.add(tuple(tuple(b) for b in box))
    return sorted(out)


def maximal_boxes(lows, highs) -> list:
    """Maximal axis-aligned boxes of the union of closed boxes ``[lows[i], highs[i]]`` (module docstring).

    Parameters
    ----------
    lows, highs : array_like, shape (k, n)

    Returns
    -------
    list of (ndarray (n,), ndarray (n,))
        Lower and upper corners; each box lies in the union, and every box of elementary
        boxes in the union lies in one of them (exactly when the candidate table has at most
        :data:`MAX_BOX_TABLE` entries, else the greedy growth of each elementary box).
    """
    lo, hi = np.atleast_2d(np.asarray(lows, float)), np.atleast_2d(np.asarray(highs, float))
    n = lo.shape[1]
    coords = [np.unique(np.concatenate([lo[:, k], hi[:, k]])) for k in range(n)]
    shape = tuple(len(c) - 1 for c in coords)
    # elementary box e lies in piece i iff lo_i <= c[e] and c[e + 1] <= hi_i on every axis
    occ = np.zeros(shape, bool)
    for l, h in zip(lo, hi):
        sl = tuple(slice(int(np.searchsorted(c, l[k])), int(np.searchsorted(c, h[k])))
                   for k, c in enumerate(coords))
        occ[sl] = True
    size = int(np.prod([d * d for d in shape], dtype=np.float64))
    boxes = _maximal_exact(occ) if size <= MAX_BOX_TABLE else _maximal_greedy(occ)
    return [(np.array([coords[k][a] for k, (a, _) in enumerate(b)]),
             np.array([coords[k][e + 1] for k, (_, e) in enumerate(b)])) for b in boxes]


def cover_pieces(decomp, labels) -> list:
    """``[(bit, Polytope), ...]``: convex sets inside the regions of ``labels``, for "surely in".

    Each label's axis-aligned box pieces are replaced by the maximal boxes of their union
    (:func:`maximal_boxes`); its other pieces are kept. A set inside one of them lies in the
    label's region (module docstring). Cached on the decomposition.
    """
    key = ("tubejax.spec.cover_pieces", tuple(str(l) for l in labels))
    if key in decomp._cache:
        return list(decomp._cache[key])
    by_bit = {}
    for b, P in region_pieces(decomp, labels):
        by_bit.setdefault(b, []).append(P)
    out = []
    for b in sorted(by_bit):
        boxes, other = [], []
        for P in by_bit[b]:
            bb = _box_bounds(P)
            (boxes if bb is not None else other).append(bb if bb is not None else P)
        if boxes:
            out += [(b, Polytope.box(l, h)) for l, h in maximal_boxes([l for l, _ in boxes], [h for _, h in boxes])]
        out += [(b, P) for P in other]
    decomp._cache[key] = tuple(out)
    return out


def inside_mask(pieces, P) -> int:
    """Bit mask of the pieces that contain the closed polytope ``P`` (within :data:`INSIDE_TOL`).

    Give it :func:`cover_pieces` to test "surely in a region" rather than "in one of its pieces"."""
    out = 0
    for b, Q in pieces:
        if float(np.max(Q.violation(P.vertices))) <= INSIDE_TOL:
            out |= 1 << b
    return out
