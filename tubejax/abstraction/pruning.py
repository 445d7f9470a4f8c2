"""Sound necessary conditions that drop pairs and horizons before any solver
(the conditions, the reasons counted and the directions: docs/math/evidence.md#why-pruning-is-sound).
Each test over-approximates support values, so it only ever proves a (pair, ``L``) infeasible, and
prunes only when violated by more than :data:`PRUNE_SLACK` ``* (1 + sum_{t<=L} ||A^t||_2)``.
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

import numpy as np
from scipy.optimize import linprog

from ..model.geometry import support, vertices_from_hrep
from ..model.system import LinearSystem
from ..model.workspace.decomposition import CellDecomposition

__all__ = ["PRUNE_REASONS", "PRUNE_SLACK", "PRUNE_CHUNK_ELEMENTS", "ReachTables", "reach_tables", "target_fits",
           "prune_pairs"]

PRUNE_REASONS = ("outside_reach", "target_too_small", "below_min_L", "set_unreachable",
                 "vertex_unreachable", "obstacle_unreachable", "safe_set_unreachable", "vertex_lp_infeasible")

#: Violation (a length) a pruning test must exceed, per unit of ``1 + sum_t ||A^t||``.
PRUNE_SLACK = 1e-7
#: At most this many distinct cell facet normals go into the shared direction set.
_MAX_SHARED_FACETS = 64
#: At most this many generalised cross products are formed for the input-reach normals.
_MAX_CROSS = 20000
_ROUND = 9


def _shape_key(P) -> bytes:
    """A cell's shape up to translation (facets and offsets about its vertex mean)."""
    c = P.vertices.mean(axis=0)
    return np.round(P.H, 12).tobytes() + np.round(P.h - P.H @ c, 12).tobytes()


def target_fits(decomp: CellDecomposition, system: LinearSystem) -> np.ndarray:
    """Whether ``P_j ⊖ W`` is non-empty for each cell, shape ``(N,)``.

    One LP per distinct cell shape up to translation (a grid map has one).
    """
    out = np.ones(decomp.n_cells, dtype=bool)
    seen = {}
    for j, P in enumerate(decomp.cells):
        key = _shape_key(P)
        if key not in seen:
            tight = P.h - support(system.W, P.H)
            res = linprog(np.zeros(P.dim), A_ub=P.H, b_ub=tight, bounds=[(None, None)] * P.dim,
                          method="highs")
            seen[key] = res.status == 0
        out[j] = seen[key]
    return out


def _unit_unique(D: np.ndarray) -> np.ndarray:
    """Unit rows, near-zero rows dropped, duplicates removed (first occurrence kept, in order)."""
    nrm = np.linalg.norm(D, axis=1)
    D = D[nrm > 1e-9 * max(float(nrm.max(initial=0.0)), 1e-300)]
    D = D / np.linalg.norm(D, axis=1, keepdims=True)
    _, first = np.unique(np.round(D, _ROUND), axis=0, return_index=True)
    return D[np.sort(first)]


def _edge_directions(U) -> np.ndarray:
    """Edge directions of the input polytope ``U``, shape ``(n_e, m)``."""
    V, m = U.vertices, U.dim
    if m == 1:
        return np.ones((1, 1))
    active = np.abs(V @ U.H.T - U.h) <= 1e-9 * (1 + np.abs(U.h))            # (n_v, n_f)
    a, b = np.triu_indices(len(V), k=1)
    shared = np.sum(active[a] & active[b], axis=1)
    return _unit_unique(V[b[shared >= m - 1]] - V[a[shared >= m - 1]])


def _cross_normals(G: np.ndarray) -> np.ndarray:
    """Unit normals of the hyperplanes spanned by ``n - 1`` of the rows of ``G`` (shape ``(g, n)``)."""
    g, n = G.shape
    if g < n - 1:
        return np.zeros((0, n))
    combos = np.array(list(itertools.islice(itertools.combinations(range(g), n - 1), _MAX_CROSS)))
    M = G[combos]                                                        # (S, n-1, n)
    cof = np.stack([(-1) ** k * np.linalg.det(np.delete(M, k, axis=2)) for k in range(n)], axis=1)
    return _unit_unique(cof) if len(cof) else np.zeros((0, n))


def separating_directions(decomp: CellDecomposition, system: LinearSystem, L_max: int):
    """The shared direction set and whether it holds every cell facet normal (else each pair
    adds the facet normals of its target).

    Returns
    -------
    D : ndarray, shape (2 h, n)
        ``h`` unit directions, then their negatives (``-D[k] == D[(k + h) % 2h]`` exactly);
        the coordinate axes ``+e_a`` are ``D[0 .. n-1]``.
    all_facets : bool
    """
    n = decomp.dim
    axes = np.eye(n)
    facets = _unit_unique(np.vstack([c.H for c in decomp.cells]))
    all_facets = len(facets) <= _MAX_SHARED_FACETS
    gens = [np.linalg.matrix_power(system.A, t) @ system.B @ g
            for t in range(L_max) for g in _edge_directions(system.U)]
    G = _unit_unique(np.array(gens)) if gens else np.zeros((0, n))
    if n == 2:
        inputs = G @ np.array([[0.0, -1.0], [1.0, 0.0]])                 # perpendiculars
    elif n > 2:
        inputs = _cross_normals(_unit_unique(np.vstack([axes, G])))
    else:
        inputs = np.zeros((0, n))
    half = _unit_unique(np.vstack([axes, facets if all_facets else np.zeros((0, n)), inputs]))
    lead = np.argmax(np.abs(half) > 1e-12, axis=1)                     # one sign per line:
    half = half * np.sign(half[np.arange(len(half)), lead])[:, None]    # first non-zero entry > 0
    half = _unit_unique(half)
    return np.vstack([half, -half]), all_facets


class ReachTables(NamedTuple):
    """Support values behind every pruning test (``L = 0 .. L_max``).

    Attributes
    ----------
    D : ndarray, shape (n_d, n)        unit directions, closed under negation
    neg : ndarray of int, shape (n_d,)  index of ``-D[k]``
    axes : ndarray of int, shape (2 n,) indices of ``+e_a`` then ``-e_a``
    cell : ndarray, shape (N, L_max + 1, n_d)  ``σ_{A^L P_i}(d)``
    inputs : ndarray, shape (L_max + 1, n_d)   ``σ_{R_L}(d)`` (``R_0 = {0}``)
    target : ndarray, shape (N, n_d)           upper bound on ``σ_{P_j ⊖ W}(d)``
    tol : ndarray, shape (L_max + 1,)          violation a test must exceed at ``L``
    all_facets : bool                          ``D`` holds every cell facet normal
    """

    D: np.ndarray
    neg: np.ndarray
    axes: np.ndarray
    cell: np.ndarray
    inputs: np.ndarray
    target: np.ndarray
    tol: np.ndarray
    all_facets: bool


def _shrunk_vertices(decomp: CellDecomposition, system: LinearSystem):
    """Vertices of ``P_j ⊖ W`` per cell (one computation per shape), or None where unavailable."""
    out, seen = [], {}
    for P in decomp.cells:
        key = _shape_key(P)
        c = P.vertices.mean(axis=0)
        if key not in seen:
            try:
                seen[key] = (vertices_from_hrep(P.H, P.h - support(system.W, P.H)), c)
            except ValueError:                                 # empty, or no interior
                seen[key] = None
        hit = seen[key]
        out.append(None if hit is None else hit[0] + (c - hit[1]))
    return out


def _padded_vertices(decomp: CellDecomposition, which=None) -> np.ndarray:
    """Cell vertices padded (by repeating the first) to one count, shape ``(N, nv_max, n)``."""
    V, cnt = decomp.padded_vertices()
    if which is not None:
        V, cnt = V[which], cnt[which]
    if np.all(cnt == V.shape[1]):
        return V
    return np.where((np.arange(V.shape[1])[None, :] < cnt[:, None])[:, :, None], V, V[:, :1])


def reach_tables(decomp: CellDecomposition, system: LinearSystem, L_max: int) -> ReachTables:
    """Per-cell and per-horizon support values; ``O(N L_max n_d)`` memory, no pair is formed."""
    A, B, U = system.A, system.B, system.U
    n = decomp.dim
    D, all_facets = separating_directions(decomp, system, L_max)
    h = len(D) // 2
    neg = (np.arange(len(D)) + h) % len(D)
    axes = np.concatenate([np.arange(n), np.arange(n) + h])
    V = _padded_vertices(decomp)
    Apow = [np.eye(n)]
    for _ in range(L_max):
        Apow.append(A @ Apow[-1])
    cell = np.stack([np.max(V @ (D @ Ap).T, axis=1) for Ap in Apow], axis=1)   # (N, L+1, n_d)
    su = np.array([U.support(D @ Ap @ B) for Ap in Apow[:L_max]])               # (L, n_d)
    inputs = np.vstack([np.zeros((1, len(D))), np.cumsum(su, axis=0)])
    fallback = np.stack([c.support(D) for c in decomp.cells]) - support(system.W, D)[None]
    target = fallback.copy()
    for j, Vs in enumerate(_shrunk_vertices(decomp, system)):
        if Vs is not None:
            target[j] = np.minimum(fallback[j], np.max(Vs @ D.T, axis=0))
    norms = np.array([np.linalg.norm(Ap, 2) for Ap in Apow])
    tol = PRUNE_SLACK * (1.0 + np.cumsum(norms))
    return ReachTables(D, neg, axes, cell, inputs, target, tol, all_facets)


def _facet_tests(decomp, system, T: ReachTables, src, dst):
    """Set-level and vertex tests along the facet normals of each pair's own ``P_j``.

    Returns ``(set_cut, vertex_cut)``, each of shape ``(K, L_max + 1)``.
    """
    A, B, U, W = system.A, system.B, system.U, system.W
    L1 = T.cell.shape[1]
    fmax = max(c.H.shape[0] for c in decomp.cells)
    set_cut = np.zeros((len(src), L1), dtype=bool)
    vert_cut = np.zeros((len(src), L1), dtype=bool)
    V = _padded_vertices(decomp, src)                                           # (K, nv, n)
    Hj = np.stack([np.vstack([decomp.cells[j].H, np.repeat(decomp.cells[j].H[:1], fmax - len(decomp.cells[j].H), 0)])
                   for j in dst])                                               # (K, f, n)
    hj = np.stack([np.concatenate([decomp.cells[j].h, np.repeat(decomp.cells[j].h[:1], fmax - len(decomp.cells[j].h))])
                   for j in dst])
    shr = hj - support(W, Hj)                                                    # P_j ⊖ W offsets
    acc = np.zeros(Hj.shape[:2])
    M = np.eye(A.shape[0])
    for L in range(L1):
        proj = np.einsum("kfn,kvn->kfv", Hj @ M, V)                             # H_r . A^L v
        if L > 0:
            acc = acc + U.support(-(Hj @ np.linalg.matrix_power(A, L - 1) @ B))  # σ_{R_L}(-H_r)
        gap = shr + T.tol[L] + acc
        set_cut[:, L] = np.any(proj.min(axis=2) > gap, axis=1)
        vert_cut[:, L] = np.any(proj.max(axis=2) > gap, axis=1)
        M = A @ M
    return set_cut, vert_cut


#: Elements of one temporary ``(pairs, L_max, directions)`` array of :func:`prune_pairs` at most
#: (32 MB of float64): the pairs are tested in chunks this small, whatever ``L_max``.
PRUNE_CHUNK_ELEMENTS = 1 << 22


def prune_pairs(decomp: CellDecomposition, system: LinearSystem, T: ReachTables, src, dst,
                chunk: int = 16384):
    """The case-independent tests on candidate pairs, each horizon ``L = 1 .. L_max``.

    Parameters
    ----------
    src, dst : ndarray of int, shape (K,)
        Candidate pairs (targets with ``P_j ⊖ W`` non-empty).
    chunk : int
        Pairs tested at once, at most; fewer when ``L_max`` is large, so that no temporary array
        exceeds :data:`PRUNE_CHUNK_ELEMENTS` (16,384 pairs at ``L_max = 1000`` would take GBs).

    Returns
    -------
    keep : ndarray of bool, shape (K, L_max)
        ``keep[k, L-1]`` is False when horizon ``L`` is infeasible for sure.
    reach1 : ndarray of bool, shape (K,)
        Whether ``A P_i ⊕ B U`` may meet ``P_j ⊖ W`` (False proves (O) fails: in the obstacle
        case no horizon works).
    counts : dict
        Pruned instances under ``below_min_L``, ``set_unreachable``, ``vertex_unreachable``.
    """
    K = len(src)
    L_max = T.cell.shape[1] - 1
    keep = np.zeros((K, L_max), dtype=bool)
    reach1 = np.zeros(K, dtype=bool)
    counts = {"below_min_L": 0, "set_unreachable": 0, "vertex_unreachable": 0}
    inp, inp_neg = T.inputs[None, 1:, :], T.inputs[None, 1:, T.neg]            # (1, L, n_d)
    tol = T.tol[None, 1:, None]
    Lidx = np.arange(1, L_max + 1)[None, :]
    chunk = max(1, min(int(chunk), PRUNE_CHUNK_ELEMENTS // max(1, L_max * T.cell.shape[2])))
    for c0 in range(0, K, chunk):
        s, d = src[c0:c0 + chunk], dst[c0:c0 + chunk]
        cell = T.cell[s, 1:, :]                                                 # (c, L, n_d)
        tgt = T.target[d][:, None, :]                                           # (c, 1, n_d)
        sep = cell + inp + tgt[:, :, T.neg] < -tol                              # reach set below P_j ⊖ W
        set_cut = np.any(sep, axis=2)
        vert_cut = np.any(cell - tgt - inp_neg > tol, axis=2)                   # A^L P_i ⊄ T_{j,L}
        if not T.all_facets:
            fs, fv = _facet_tests(decomp, system, T, s, d)
            set_cut |= fs[:, 1:]
            vert_cut |= fv[:, 1:]
        axis_sep = np.any(sep[:, :, T.axes], axis=2)
        first = np.where(axis_sep.all(axis=1), L_max + 1, np.argmin(axis_sep, axis=1) + 1)
        below = Lidx < first[:, None]
        cut_set = ~below & set_cut
        cut_vert = ~below & ~set_cut & vert_cut
        counts["below_min_L"] += int(below.sum())
        counts["set_unreachable"] += int(cut_set.sum())
        counts["vertex_unreachable"] += int(cut_vert.sum())
        keep[c0:c0 + chunk] = ~(below | set_cut | vert_cut)
        reach1[c0:c0 + chunk] = ~set_cut[:, 0]
    return keep, reach1, counts
