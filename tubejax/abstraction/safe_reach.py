"""Pruning with the state constraints: the tube stays in ``S`` before it reaches ``P_j``
(condition (S) of :func:`constrained_reach`; every box is an outer bound of the true set, so only
infeasible horizons are dropped).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..model.geometry import support
from .pruning import ReachTables, _padded_vertices
from ..model.system import LinearSystem
from ..model.workspace.decomposition import CellDecomposition

__all__ = ["constrained_reach"]

#: Threads of :func:`constrained_reach` (one chunk of pairs each at a time).
_THREADS = min(2, os.cpu_count() or 1)


def _clip_to_hull(a, b, lo_i, hi_i, lo_j, hi_j, tol):
    """Shrink boxes ``[a, b]`` (shape ``(n, k, nv)``: axis first) to the bounding box of their part
    in ``co(P_i u P_j)`` for box cells (``lo_*``, ``hi_*`` of shape ``(n, k, 1)``).

    ``co(P_i u P_j)`` is the union of the boxes ``B(λ) = λ P_i + (1-λ) P_j``, ``λ in [0, 1]``;
    ``[a, b]`` meets ``B(λ)`` iff ``λ`` lies in an interval ``Λ`` (two linear conditions per
    axis), and the part of ``[a, b]`` in the hull lies in the box spanned by ``B(min Λ)`` and
    ``B(max Λ)``. Bounds are widened by ``tol`` (a length). Returns the clipped ``(a, b)``; an
    empty one has ``a > b`` (finite) in every coordinate.
    """
    lam_lo = np.zeros(a.shape[1:])
    lam_hi = np.ones(a.shape[1:])
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
        lam_hi = np.minimum(lam_hi, np.min(np.where(pos, ratio, np.inf), axis=0))
        lam_lo = np.maximum(lam_lo, np.max(np.where(neg, ratio, -np.inf), axis=0))
        dead = np.any(~pos & ~neg & (r < 0), axis=0)    # q = 0 and the face is missed
        lam_hi = np.where(dead, -np.inf, lam_hi)
    lam_lo = lam_lo - 1e-12
    lam_hi = lam_hi + 1e-12
    empty = lam_lo > lam_hi
    l0, l1 = np.clip(lam_lo, 0, 1)[None], np.clip(lam_hi, 0, 1)[None]
    box_lo = np.minimum(lo_j + l0 * (lo_i - lo_j), lo_j + l1 * (lo_i - lo_j)) - tol
    box_hi = np.maximum(hi_j + l0 * (hi_i - hi_j), hi_j + l1 * (hi_i - hi_j)) + tol
    a = np.maximum(a, box_lo)
    b = np.where(empty[None], a - 1.0, np.minimum(b, box_hi))           # empty: b < a, kept finite
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


def _propagate_two_axis_rows(a, b, H, g, ia, ib):
    """Shrink boxes ``[a, b]`` (shape ``(n, k, nv)``: axis first) to the halfspaces ``H x <= g``
    (per pair, shapes ``(k, F, n)``, ``(k, F)``) by one sweep of bound propagation, for rows with
    two nonzeros, on axes ``ia[f]`` and ``ib[f]`` (the facets of :func:`_hull_facets_of_translates`):
    for a row ``h`` and one of its axes ``e`` with ``h_e > 0``, ``x_e <= (g - min(h_o a_o, h_o
    b_o)) / h_e`` over its other axis ``o`` (and ``>=`` for ``h_e < 0``). Every point of the box
    in the halfspaces stays.
    """
    F = np.arange(len(ia))
    ca, cb = H[:, F, ia].T[:, :, None], H[:, F, ib].T[:, :, None]              # (F, k, 1)
    gk = g.T[:, :, None]
    lo_a = np.minimum(ca * a[ia], ca * b[ia])                                  # (F, k, nv)
    lo_b = np.minimum(cb * a[ib], cb * b[ib])
    with np.errstate(divide="ignore", invalid="ignore"):
        on_a, on_b = (gk - lo_b) / ca, (gk - lo_a) / cb
    up = np.concatenate([np.where(ca > 1e-12, on_a, np.inf), np.where(cb > 1e-12, on_b, np.inf)])     # (2F, k, nv)
    dn = np.concatenate([np.where(ca < -1e-12, on_a, -np.inf), np.where(cb < -1e-12, on_b, -np.inf)])
    on = np.concatenate([ia, ib])                                              # the axis each bound is on
    a, b = a.copy(), b.copy()
    for e in range(a.shape[0]):
        rows = on == e
        b[e] = np.minimum(b[e], np.min(up[rows], axis=0, initial=np.inf))
        a[e] = np.maximum(a[e], np.max(dn[rows], axis=0, initial=-np.inf))
    return a, b


def constrained_reach(decomp: CellDecomposition, system: LinearSystem, T: ReachTables, src, dst,
                      obstacle, chunk: int = 4096, keep: np.ndarray | None = None) -> np.ndarray:
    """Horizons at which every vertex may reach ``P_j ⊖ W`` while staying in ``S ⊖ W``
    (**safe_set_unreachable**; why this is sound: docs/math/evidence.md#why-pruning-is-sound).

    Boxes bound Lemma 1's ``w = 0`` trajectory of each vertex from outside: ``X_0 = {v_k}``, ``X_l`` the
    bounding box of ``A X_{l-1} ⊕ B box(U)`` within an outer box of ``S ⊖ W`` (for box cells also
    clipped to ``P_ij``, :func:`_clip_to_hull`). Horizon ``L`` is dropped when the box of
    ``A X_{L-1} ⊕ B box(U)`` misses that of ``P_j ⊖ W`` by more than the tolerance, and every horizon
    after ``l`` when ``X_l`` is empty.

    Parameters
    ----------
    src, dst : ndarray of int, shape (K,)
    obstacle : ndarray of bool, shape (K,)
    keep : ndarray of bool, shape (K, L_max), optional
        The horizons still to decide: a pair is followed only while one of its later horizons
        is kept (the answer for the others is False; the caller drops them anyway).

    Returns
    -------
    ndarray of bool, shape (K, L_max)
        False where horizon ``L`` is infeasible for sure (or not asked, with ``keep``).
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
    # every cell has a box's counts (2^n vertices, 2n facets); the hull clip and the translates' facets
    # below read the cells' bounding boxes (lo, hi), which contain every cell
    cells_box_like = all(c.n_vertices == 2 ** n and c.H.shape[0] == 2 * n for c in decomp.cells)
    half = (hi - lo) / 2
    translates = cells_box_like and bool(np.all(np.abs(half - half[0]) <= 1e-12 * (1 + np.abs(half[0]))))
    t_hi, t_lo = T.target[:, T.axes[:n]], -T.target[:, T.axes[n:]]
    V = _padded_vertices(decomp)
    out = np.zeros((len(src), L_max), dtype=bool)

    AT, absAT, absBT = A.T, absA.T, absB.T

    def run(c0):                        # boxes axis first, (n, pairs, vertices): reductions over axes are cheap
        s, d, ob = src[c0:c0 + chunk], dst[c0:c0 + chunk], obstacle[c0:c0 + chunk]
        j = np.where(ob, s, d)                                                        # S = co(P_s u P_j)
        s_lo = (np.minimum(lo[s], lo[j]) + w_neg).T[:, :, None]                       # box of S ⊖ W
        s_hi = (np.maximum(hi[s], hi[j]) - w_pos).T[:, :, None]
        if translates:
            ia, ib = (np.concatenate([t, t]) for t in np.triu_indices(n, k=1))    # the facets' two axes
            Hf, gf = _hull_facets_of_translates((lo[s] + hi[s]) / 2, (lo[j] + hi[j]) / 2, half[0], system.W, 0.0)
        c = np.ascontiguousarray(np.moveaxis(V[s], 2, 0))                             # (n, k, nv)
        r = np.zeros_like(c)
        live = np.arange(len(s))            # the pairs whose X_{L-1} is not empty (only they are computed)
        for L in range(1, L_max + 1):
            if not live.size:
                break
            tol = T.tol[L]
            s_, d_, j_ = s[live], d[live], j[live]
            c = np.ascontiguousarray(np.moveaxis(np.moveaxis(c, 0, 2) @ AT + u_c @ B.T, 2, 0))
            r = np.ascontiguousarray(np.moveaxis(np.moveaxis(r, 0, 2) @ absAT + u_r @ absBT, 2, 0))
            meet = np.all((c - r <= t_hi[d_].T[:, :, None] + tol) & (t_lo[d_].T[:, :, None] <= c + r + tol), axis=0)
            out[c0 + live, L - 1] = np.all(meet, axis=1)
            a = np.maximum(c - r, s_lo[:, live] - tol)                               # X_L for the next step
            b = np.minimum(c + r, s_hi[:, live] + tol)
            if cells_box_like:
                a, b = _clip_to_hull(a, b, lo[s_].T[:, :, None], hi[s_].T[:, :, None], lo[j_].T[:, :, None],
                                     hi[j_].T[:, :, None], tol)
            if translates:
                a, b = _propagate_two_axis_rows(a, b, Hf[live], gf[live] + tol, ia, ib)
            alive = np.all(a <= b, axis=(0, 2))       # X_L empty: every later horizon is infeasible too
            if keep is not None:                      # nothing kept after L: no need to go on
                alive &= keep[c0 + live, L:].any(axis=1)
            live, a, b = live[alive], a[:, alive], b[:, alive]
            c, r = (a + b) / 2, np.maximum(b - a, 0) / 2

    starts = range(0, len(src), chunk)
    n_threads = min(_THREADS, len(starts))
    if n_threads > 1:                 # NumPy releases the GIL in its loops: chunks run side by side
        with ThreadPoolExecutor(n_threads) as ex:
            list(ex.map(run, starts))             # each chunk writes its own rows of ``out``
    else:
        for c0 in starts:
            run(c0)
    return out
