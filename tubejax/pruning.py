"""Sound necessary conditions that drop pairs and horizons before any solver.

**Why they hold.** Let Problem 2 be feasible for ``(i, j, L)``. With ``w = 0``, Lemma 1 steers
every ``x(0) in P_i`` -- in particular every vertex ``v_k`` -- through the tube: at each step
``x(l) in Q_l`` gives an input ``u in U`` (the convex combination of the vertex inputs) with
``A x(l) + B u in Q_{l+1} ⊖ W``. At the last step ``Q_L ⊖ W ⊆ P_j ⊖ W`` (C3), so

    (V)  x_k(L) in (A^L v_k ⊕ R_L) ∩ (P_j ⊖ W)  for every vertex k,   R_L = ⊕_{t<L} A^t B U,

and, in the obstacle case, ``x(L-1) in Q_{L-1} ⊆ P_i`` (``x(0) in P_i`` when ``L = 1``), so

    (O)  (A P_i ⊕ B U) ∩ (P_j ⊖ W) ≠ ∅.

``P_j ⊖ W = {x : H_j x <= h_j - σ_W(H_j)}`` exactly; it must be non-empty (**target_too_small**).
(V) says ``A^L P_i ⊆ T_{j,L} = (P_j ⊖ W) ⊕ (-R_L)``, i.e. for every direction ``d``

    σ_{A^L P_i}(d) <= σ_{P_j ⊖ W}(d) + σ_{R_L}(-d),

so one direction violating it proves ``(i, j, L)`` infeasible (**vertex_unreachable**: some
vertex cannot reach ``P_j ⊖ W``; the test takes the MIN over the vertices of ``d . A^L v_k``,
where a set-level test takes the MAX). Its weaker set-level form, ``A^L P_i ⊕ R_L`` missing
``P_j ⊖ W`` (a separating direction: ``σ_{A^L P_i}(d) + σ_{R_L}(d) < -σ_{P_j ⊖ W}(-d)``), is
counted first (**set_unreachable**), and its axis directions alone give the distance bound:
the first ``L`` whose reach box meets the box of ``P_j ⊖ W`` (**below_min_L** counts the
horizons under it). (O) is the set-level test with ``L = 1``, which then drops every
horizon of an obstacle-case pair (**obstacle_unreachable**). Pairs whose reach boxes miss
``P_j ⊖ W`` at every ``L`` are never candidates (**outside_reach**,
:mod:`tubejax.candidates`).

Every bound used is an over-approximation of the true support values (``σ_{P_j ⊖ W}`` from
the exact vertices of ``P_j ⊖ W``, or ``σ_{P_j} - σ_W`` where those are not available), so a
test only ever proves emptiness. A verified tube satisfies Problem 2 only up to ``1e-9`` per
row (SPEC section 4), and that slack can grow by ``||A^t||`` per step; so a test prunes only
when it is violated by more than :data:`PRUNE_SLACK` ``* (1 + sum_{t<=L} ||A^t||_2)``, far above
anything a verified tube can hide, and nothing that could become an edge is dropped.

Directions: the coordinate axes, the facet normals of the cells (when there are few distinct
ones; otherwise each pair also uses the facet normals of its own ``P_j``), and the facet
normals of the ``R_L``: in 2-D the normals of ``A^t B g`` for the edge directions ``g`` of
``U``; in n-D the generalised cross products of ``n - 1`` of those and the axes. In 2-D, and
for box cells in n-D, these include every facet normal of ``T_{j,L}``, so the vertex test is
exact there: it drops exactly the horizons at which some vertex of ``P_i`` cannot reach
``P_j ⊖ W``.
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

import numpy as np
from scipy.optimize import linprog

from .geometry import support, vertices_from_hrep
from .system import LinearSystem
from .workspace.decomposition import CellDecomposition

__all__ = ["PRUNE_REASONS", "PRUNE_SLACK", "ReachTables", "reach_tables", "target_fits", "prune_pairs",
           "constrained_reach"]

PRUNE_REASONS = ("outside_reach", "target_too_small", "below_min_L", "set_unreachable",
                 "vertex_unreachable", "obstacle_unreachable", "safe_set_unreachable")

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


def prune_pairs(decomp: CellDecomposition, system: LinearSystem, T: ReachTables, src, dst,
                chunk: int = 16384):
    """The case-independent tests on candidate pairs, each horizon ``L = 1 .. L_max``.

    Parameters
    ----------
    src, dst : ndarray of int, shape (K,)
        Candidate pairs (targets with ``P_j ⊖ W`` non-empty).

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


def _clip_to_hull(a, b, lo_i, hi_i, lo_j, hi_j, tol):
    """Shrink boxes ``[a, b]`` (shape ``(k, nv, n)``) to the bounding box of their part in
    ``co(P_i u P_j)`` for box cells (``lo_*``, ``hi_*`` of shape ``(k, 1, n)``).

    ``co(P_i u P_j)`` is the union of the boxes ``B(λ) = λ P_i + (1-λ) P_j``, ``λ in [0, 1]``;
    ``[a, b]`` meets ``B(λ)`` iff ``λ`` lies in an interval ``Λ`` (two linear conditions per
    axis), and the part of ``[a, b]`` in the hull lies in the box spanned by ``B(min Λ)`` and
    ``B(max Λ)``. Bounds are widened by ``tol`` (a length). Returns the clipped ``(a, b)``; an
    empty one has ``a > b`` (finite) in every coordinate.
    """
    lam_lo = np.zeros(a.shape[:2])
    lam_hi = np.ones(a.shape[:2])
    for p, q, ok in ((lo_j, lo_i - lo_j, b + tol), (hi_j, hi_i - hi_j, None)):
        # lower faces: p + λ q <= b + tol; upper faces: p + λ q >= a - tol
        rhs = (b + tol - p) if ok is not None else (a - tol - p)
        sign = 1.0 if ok is not None else -1.0
        qq = sign * q                                   # condition: λ qq <= sign * rhs
        r = sign * rhs
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = r / qq
        pos = np.broadcast_to(qq > 0, r.shape)
        neg = np.broadcast_to(qq < 0, r.shape)
        lam_hi = np.minimum(lam_hi, np.min(np.where(pos, ratio, np.inf), axis=2))
        lam_lo = np.maximum(lam_lo, np.max(np.where(neg, ratio, -np.inf), axis=2))
        dead = np.any(~pos & ~neg & (r < 0), axis=2)    # q = 0 and the face is missed
        lam_hi = np.where(dead, -np.inf, lam_hi)
    lam_lo = lam_lo - 1e-12
    lam_hi = lam_hi + 1e-12
    empty = lam_lo > lam_hi
    l0, l1 = np.clip(lam_lo, 0, 1)[..., None], np.clip(lam_hi, 0, 1)[..., None]
    box_lo = np.minimum(lo_j + l0 * (lo_i - lo_j), lo_j + l1 * (lo_i - lo_j)) - tol
    box_hi = np.maximum(hi_j + l0 * (hi_i - hi_j), hi_j + l1 * (hi_i - hi_j)) + tol
    a = np.maximum(a, box_lo)
    b = np.where(empty[..., None], a - 1.0, np.minimum(b, box_hi))      # empty: b < a, kept finite
    return a, b


def _hull_facets_of_translates(c_i, c_j, half, W, tol):
    """Facets of ``S ⊖ W`` beyond the axes, for ``S = co(P_i u P_j)`` with ``P_j`` a translate of the box ``P_i``.

    Then ``S = P_i ⊕ [0, δ]`` (``δ = c_j - c_i``), a zonotope whose facet normals are the axes and,
    for each pair of axes ``(a, b)``, ``±(δ_b e_a - δ_a e_b)``; ``σ_S(d) = σ_{P_i}(d) + max(0, d . δ)``
    and ``S ⊖ W = {x : H x <= σ_S(H) - σ_W(H)}`` exactly.

    Parameters
    ----------
    c_i, c_j : ndarray, shape (k, n)    box centres
    half : ndarray, shape (n,)          box half-widths

    Returns
    -------
    H : ndarray, shape (k, F, n)        unit normals (zero rows where ``δ_a = δ_b = 0``)
    g : ndarray, shape (k, F)           offsets of ``S ⊖ W`` plus ``tol`` (``inf`` on zero rows)
    """
    k, n = c_i.shape
    delta = c_j - c_i
    a_idx, b_idx = np.triu_indices(n, k=1)
    H = np.zeros((k, len(a_idx), n))
    H[:, np.arange(len(a_idx)), a_idx] = delta[:, b_idx]
    H[:, np.arange(len(a_idx)), b_idx] = -delta[:, a_idx]
    nrm = np.linalg.norm(H, axis=2, keepdims=True)
    zero = nrm[..., 0] <= 1e-12
    H = np.where(zero[..., None], 0.0, H / np.where(zero[..., None], 1.0, nrm))
    H = np.concatenate([H, -H], axis=1)
    zero = np.concatenate([zero, zero], axis=1)
    sig = np.einsum("kfn,kn->kf", H, c_i) + np.abs(H) @ half + np.maximum(0.0, np.einsum("kfn,kn->kf", H, delta))
    g = np.where(zero, np.inf, sig - support(W, H) + tol)
    return H, g


def _propagate_halfspaces(a, b, H, g, sweeps: int = 1):
    """Shrink boxes ``[a, b]`` (shape ``(k, nv, n)``) to the halfspaces ``H x <= g`` (per pair,
    shapes ``(k, F, n)``, ``(k, F)``) by bound propagation: for a row ``h`` and axis ``e`` with
    ``h_e > 0``, ``x_e <= (g - sum_{o != e} min(h_o a_o, h_o b_o)) / h_e`` (and ``>=`` for
    ``h_e < 0``). Every point of the box in the halfspaces stays; sound for any number of sweeps.
    """
    Hk = H[:, None, :, :]                                              # (k, 1, F, n)
    gk = g[:, None, :, None]
    for _ in range(sweeps):
        lo_t = np.minimum(Hk * a[:, :, None, :], Hk * b[:, :, None, :])    # (k, nv, F, n)
        rest = np.sum(lo_t, axis=3, keepdims=True) - lo_t
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = (gk - rest) / Hk
        big = np.abs(Hk) > 1e-12
        b = np.minimum(b, np.min(np.where(big & (Hk > 0), bound, np.inf), axis=2))
        a = np.maximum(a, np.max(np.where(big & (Hk < 0), bound, -np.inf), axis=2))
    return a, b


def constrained_reach(decomp: CellDecomposition, system: LinearSystem, T: ReachTables, src, dst,
                      obstacle, chunk: int = 4096) -> np.ndarray:
    """Horizons at which every vertex may reach ``P_j ⊖ W`` while staying in ``S ⊖ W``.

    (S) Along Lemma 1's ``w = 0`` trajectory of vertex ``v_k``, ``x(l) in Q_l ⊖ W ⊆ S ⊖ W`` for
    ``l = 1 .. L-1`` (C2) and ``x(L) in P_j ⊖ W`` (C3). Boxes bound these sets from outside:
    ``X_0 = {v_k}``, ``X_l`` the bounding box of ``A X_{l-1} ⊕ B box(U)`` intersected with an
    outer box of ``S ⊖ W``: ``S``'s bounding box shrunk by ``σ_W(±e_a)`` (``S = P_ij`` in the
    free case, ``P_i`` in the obstacle case), and for box cells also the bounding box of the
    part of ``X_l`` inside ``P_ij`` (:func:`_clip_to_hull`). When the box of
    ``A X_{L-1} ⊕ B box(U)`` misses the box of ``P_j ⊖ W`` by more than the tolerance, horizon
    ``L`` is infeasible; when ``X_l`` is empty, so is every horizon after ``l``
    (**safe_set_unreachable**).

    Parameters
    ----------
    src, dst : ndarray of int, shape (K,)
    obstacle : ndarray of bool, shape (K,)

    Returns
    -------
    ndarray of bool, shape (K, L_max)
        False where horizon ``L`` is infeasible for sure.
    """
    n = decomp.dim
    L_max = T.cell.shape[1] - 1
    A, B = system.A, system.B
    absA, absB = np.abs(A), np.abs(B)
    u_lo, u_hi = system.U.bounding_box()
    u_c, u_r = (u_lo + u_hi) / 2, (u_hi - u_lo) / 2
    w_pos = support(system.W, np.eye(n))
    w_neg = support(system.W, -np.eye(n))
    lo, hi = decomp.cell_boxes()
    boxes = all(c.n_vertices == 2 ** n and c.H.shape[0] == 2 * n for c in decomp.cells)
    half = (hi - lo) / 2
    translates = boxes and bool(np.all(np.abs(half - half[0]) <= 1e-12 * (1 + np.abs(half[0]))))
    t_hi, t_lo = T.target[:, T.axes[:n]], -T.target[:, T.axes[n:]]
    V = _padded_vertices(decomp)
    out = np.ones((len(src), L_max), dtype=bool)
    for c0 in range(0, len(src), chunk):
        s, d, ob = src[c0:c0 + chunk], dst[c0:c0 + chunk], obstacle[c0:c0 + chunk]
        j = np.where(ob, s, d)                                                        # S = co(P_s u P_j)
        s_lo = np.minimum(lo[s], lo[j]) + w_neg                                       # box of S ⊖ W
        s_hi = np.maximum(hi[s], hi[j]) - w_pos
        c = V[s]                                                                      # (k, nv, n)
        r = np.zeros_like(c)
        alive = np.ones(len(s), dtype=bool)
        for L in range(1, L_max + 1):
            tol = T.tol[L]
            c = c @ A.T + u_c @ B.T
            r = r @ absA.T + u_r @ absB.T
            meet = np.all((c - r <= t_hi[d][:, None] + tol) & (t_lo[d][:, None] <= c + r + tol), axis=2)
            out[c0:c0 + chunk, L - 1] = alive & np.all(meet, axis=1)
            a = np.maximum(c - r, s_lo[:, None] - tol)                               # X_L for the next step
            b = np.minimum(c + r, s_hi[:, None] + tol)
            if boxes:
                a, b = _clip_to_hull(a, b, lo[s][:, None], hi[s][:, None], lo[j][:, None], hi[j][:, None], tol)
            if translates:
                if L == 1:
                    Hf, gf = _hull_facets_of_translates((lo[s] + hi[s]) / 2, (lo[j] + hi[j]) / 2, half[0], system.W, 0.0)
                a, b = _propagate_halfspaces(a, b, Hf, gf + tol)
            alive &= np.all(a <= b, axis=(1, 2))
            a, b = np.where(alive[:, None, None], a, 0.0), np.where(alive[:, None, None], b, 0.0)
            c, r = (a + b) / 2, np.maximum(b - a, 0) / 2
    return out
