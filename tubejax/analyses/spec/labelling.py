"""Which labelled regions each tube set can meet: exact, vectorised polytope tests.

Along edge ``(i, j, L)`` the state is in ``Q_l = p_l + eps_l Z_i`` at step ``l = 1..L``. For every
step and every piece ``P_c`` of a region (:mod:`tubejax.analyses.spec.regions`) whose label is a
proposition of the automaton this module decides **may** (``Q_l`` meets the closed piece: support
functions over the facet normals of ``Z (+) (-P_c)``, one hull per ``(Z, cell)``, closer than
:data:`MEET_TOL` counts) and **must** (``Q_l`` inside a
:func:`~tubejax.analyses.spec.regions.cover_pieces` piece up to ``VERIFY_TOL``, and ``P_j``'s label
at ``l = L``). The letter read at step ``l`` is then some ``S`` with ``must_l <= S <= may_l``: a
sound over-approximation. Why each test is exact: docs/math/control.md#which-regions-a-tube-set-may-meet.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import networkx as nx

from ...model.geometry import Polytope
from ...lp.evidence.verdict import VERIFY_TOL
from ...lp.evidence.registry import tube_methods
from .regions import cover_pieces, inside_mask, region_pieces

__all__ = ["EdgeLetters", "edge_letters", "cell_letters", "start_letters", "map_alphabet", "submasks", "MEET_TOL",
           "minkowski_normals"]

#: Two sets closer than this (along some facet normal of their difference) count as meeting.
MEET_TOL = 1e-8


@dataclass(frozen=True)
class EdgeLetters:
    """Possible letters along every edge.

    Attributes
    ----------
    must, may : ndarray of int64, shape (E, L_max)
        Bit masks over the automaton's propositions for steps ``l = 1..L`` (column
        ``l - 1``); columns ``>= L`` of an edge are 0.
    L : ndarray of int, shape (E,)
    """

    must: np.ndarray
    may: np.ndarray
    L: np.ndarray

    def distinct(self) -> tuple[list, np.ndarray]:
        """The distinct letter sets, each ``[(must_l, may_l), ...]`` for ``l = 1..L``, and the index
        of each edge's set, shape ``(E,)`` (edges with the same letter sets share the planners' work)."""
        E, Lmax = self.must.shape
        valid = np.arange(Lmax)[None, :] < self.L[:, None]
        pair = np.stack([np.where(valid, self.must, -1), np.where(valid, self.may, -1)], -1)
        keys, inv = np.unique(pair.reshape(E, -1), axis=0, return_inverse=True)
        return [[(int(k[2 * l]), int(k[2 * l + 1])) for l in range(Lmax) if k[2 * l] >= 0] for k in keys], inv.ravel()


def submasks(free: int):
    """All submasks of ``free`` (including 0 and ``free``)."""
    s = free
    while True:
        yield s
        if s == 0:
            return
        s = (s - 1) & free


def start_letters(decomp, labels, cell: int) -> list:
    """The letters a state anywhere in the closed ``cell`` can read (:func:`cell_letters`, within
    :func:`map_alphabet`)."""
    must, may = cell_letters(decomp, labels, cell)
    ok = map_alphabet(decomp, labels)
    return [must | s for s in submasks(may & ~must) if ok[must | s]]


def minkowski_normals(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Unit facet normals of ``co(A) (+) (-co(B))``, shape ``(m, n)``, from vertex arrays ``A (a, n)``, ``B (b, n)``."""
    D = (A[:, None, :] - B[None, :, :]).reshape(-1, A.shape[1])
    return Polytope.from_vertices(D).H


def edge_letters(ts, labels, edges=None) -> EdgeLetters:
    """``must``/``may`` masks of every step of every edge (module docstring).

    Parameters
    ----------
    ts : TransitionSystem
        Built with method ``'tube'`` (the stored tubes give ``Q_l``).
    labels : sequence of str
        Region label of each proposition bit (``DFA.labels``).
    edges : sequence of int, optional
        Edge indices (default: all).

    Returns
    -------
    EdgeLetters
    """
    if ts.method not in tube_methods():
        raise ValueError(f"temporal-logic planning needs the tubes of method {' or '.join(map(repr, tube_methods()))}; this "
                         f"transition system was built with method {ts.method!r}")
    ids = np.arange(ts.n_edges) if edges is None else np.asarray(edges, dtype=int)
    E = len(ids)
    arrays = ts.edge_arrays()
    Ls = arrays.L[ids].astype(int)
    Lmax = int(Ls.max()) if E else 1
    must = np.zeros((E, Lmax), np.int64)
    may = np.zeros((E, Lmax), np.int64)
    if E == 0:
        return EdgeLetters(must, may, Ls)
    d = ts.decomposition
    n = d.dim
    # every tube set Q_l of every edge, flattened: rows (edge, step)
    rows_e = np.repeat(np.arange(E), Ls)
    rows_l = np.concatenate([np.arange(L) for L in Ls])
    p = np.concatenate([np.asarray(ts.tubes[k].p, float).reshape(-1, n) for k in ids])
    eps = np.concatenate([np.asarray(ts.tubes[k].eps, float).ravel() for k in ids])
    zkey, zverts = {}, []
    zid = np.empty(E, int)
    for r, (i, j) in enumerate(zip(arrays.src[ids].tolist(), arrays.dst[ids].tolist())):
        V = np.ascontiguousarray(ts.z_of(i, j).vertices, float)
        key = (V.shape, V.tobytes())
        if key not in zkey:
            zkey[key] = len(zverts)
            zverts.append(V)
        zid[r] = zkey[key]
    zrow = zid[rows_e]
    M = np.zeros(len(p), np.int64)                    # may masks per row
    S = np.zeros(len(p), np.int64)                    # must masks per row
    groups = [np.flatnonzero(zrow == z) for z in range(len(zverts))]
    normals = {}                                      # the normals depend on the shapes only, not on where P is
    for b, P in region_pieces(d, labels):
        shape = np.ascontiguousarray(P.vertices - P.vertices[0])
        for z, (Zv, sel) in enumerate(zip(zverts, groups)):
            key = (z, shape.shape, shape.tobytes())
            if key not in normals:
                normals[key] = minkowski_normals(Zv, P.vertices)
            N = normals[key]                                          # (m, n)
            sz = np.max(N @ Zv.T, axis=1)                             # sigma_Z(a)
            sp = np.max(-N @ P.vertices.T, axis=1)                    # sigma_P(-a)
            gap = p[sel] @ N.T + eps[sel, None] * sz + sp             # (rows, m)
            meets = gap.min(axis=1) >= -MEET_TOL
            M[sel[meets]] |= np.int64(1) << b
    for b, P in cover_pieces(d, labels):
        for Zv, sel in zip(zverts, groups):
            hz = np.max(P.H @ Zv.T, axis=1)                           # sigma_Z(H_c rows)
            inside = (p[sel] @ P.H.T + eps[sel, None] * hz - P.h).max(axis=1) <= VERIFY_TOL
            S[sel[inside]] |= np.int64(1) << b
    must[rows_e, rows_l] = S
    may[rows_e, rows_l] = M
    # Q_L lies in P_j (C3): the end cell's label holds at step L
    bit = {str(l): b for b, l in enumerate(labels)}
    for r, j in enumerate(arrays.dst[ids].tolist()):
        lab = d.labels[j]
        if lab is not None and str(lab) in bit:
            must[r, Ls[r] - 1] |= np.int64(1) << bit[str(lab)]
    may |= must
    return EdgeLetters(must, may, Ls)


def _sets_meet(P, Q, cache: dict) -> bool:
    """Whether closed convex sets ``P`` and ``Q`` meet (within :data:`MEET_TOL`); normals cached by shape."""
    kp = np.ascontiguousarray(P.vertices - P.vertices[0])
    kq = np.ascontiguousarray(Q.vertices - Q.vertices[0])
    key = (kp.shape, kp.tobytes(), kq.shape, kq.tobytes())
    if key not in cache:
        cache[key] = minkowski_normals(P.vertices, Q.vertices)
    N = cache[key]
    return bool((np.max(N @ P.vertices.T, axis=1) + np.max(-N @ Q.vertices.T, axis=1)).min() >= -MEET_TOL)


def _meeting(pieces, boxes, P, cache: dict) -> list:
    """Indices of the ``pieces`` (``[(bit, Polytope)]``, bounding ``boxes``) that the closed set ``P`` meets."""
    if not pieces:
        return []
    lo, hi = boxes
    plo, phi = P.bounding_box()
    near = np.flatnonzero(np.all((lo <= phi + MEET_TOL) & (hi >= plo - MEET_TOL), axis=1))
    return [int(r) for r in near if _sets_meet(P, pieces[r][1], cache)]


def _boxes(pieces) -> tuple[np.ndarray, np.ndarray]:
    """Bounding boxes ``(lo, hi)``, each ``(len(pieces), n)``, of the pieces (``None`` without pieces)."""
    if not pieces:
        return None
    lo = np.array([P.bounding_box()[0] for _, P in pieces])
    hi = np.array([P.bounding_box()[1] for _, P in pieces])
    return lo, hi


def cell_letters(decomp, labels, cell: int) -> tuple[int, int]:
    """``(must, may)`` masks for a state anywhere in the closed cell ``cell``.

    ``must`` holds the cell's own label and every region containing the whole cell;
    ``may`` adds every region the cell meets (a neighbouring cell of the region that
    touches it, or a label box that cuts it, :mod:`tubejax.analyses.spec.regions`).
    """
    pieces = region_pieces(decomp, labels)
    P = decomp.cells[int(cell)]
    bit = {str(l): b for b, l in enumerate(labels)}
    lab = decomp.labels[int(cell)]
    must = ((1 << bit[str(lab)] if lab is not None and str(lab) in bit else 0)
            | inside_mask(cover_pieces(decomp, labels), P))
    may = must | sum({1 << pieces[r][0] for r in _meeting(pieces, _boxes(pieces), P, {})})
    return must, may


def map_alphabet(decomp, labels) -> np.ndarray:
    """``(2**k,)`` bool: the letters a state can read anywhere (a sound over-approximation).

    A point in a region piece ``c`` (:mod:`tubejax.analyses.spec.regions`: a labelled cell, or
    a label box) reads ``c``'s label plus the labels of the other pieces containing it;
    those all meet ``c`` and each other, so they form a clique of the "pieces meet"
    graph among ``c``'s neighbours. Every letter is therefore ``own(c) | S`` with
    ``S`` within the labels of such a clique (maximal cliques by
    :func:`networkx.find_cliques`). A point in no piece reads the empty letter.
    """

    key = ("tubejax.spec.map_alphabet", tuple(str(l) for l in labels))
    if key in decomp._cache:
        return decomp._cache[key].copy()
    k = len(labels)
    ok = np.zeros(1 << k, bool)
    ok[0] = True
    cache = {}
    pieces = region_pieces(decomp, labels)
    boxes = _boxes(pieces)
    for c, (bc, P) in enumerate(pieces):
        own = 1 << bc
        touch = [r for r in _meeting(pieces, boxes, P, cache) if r != c]
        G = nx.Graph()
        G.add_nodes_from(touch)
        G.add_edges_from((a, b) for i, a in enumerate(touch) for b in touch[i + 1:]
                         if _sets_meet(pieces[a][1], pieces[b][1], cache))
        for clique in nx.find_cliques(G) if touch else [[]]:
            for s in submasks(sum({1 << pieces[q][0] for q in clique})):
                ok[own | s] = True
    decomp._cache[key] = ok
    return ok.copy()
