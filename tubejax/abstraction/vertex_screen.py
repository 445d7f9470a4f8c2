"""The screening kernel of the vertex-LP rule (:mod:`tubejax.abstraction.vertex_lp`): one pair's
vertex LPs, with the rows, refuting duals and witnessing inputs kept per row structure.

A vertex LP of horizon ``L`` is ``max t  s.t.  G u + t 1 <= g - M v,  u ∈ box(U)^L,  t <= 1``
(:mod:`tubejax.abstraction.vertex_lp`). ``G`` and ``M`` depend only on the facet normals of
``S ⊖ W`` and ``P_j ⊖ W`` (the pair's *shape*) and on ``L``; ``g`` on where the pair lies, ``v``
on the vertex. Pairs arrive sorted by shape, so everything that depends on the shape and ``L``
only is computed once per run of like pairs (:class:`ShapeRows`), and so are the parts of a
weak-duality bound that depend on the dual point only (:class:`DualStore`) and the rows' values
at a witnessing input sequence (:class:`WitnessStore`). What a bound or a witness decides is
computed from the instance's own right-hand sides, as before.
"""

from __future__ import annotations

import highspy
import numpy as np

from ..lp.solvers.highs import new_highs

__all__ = ["ShapeRows", "DualStore", "WitnessStore", "screen_pairs", "dual_bounds", "dual_bound",
           "vertex_model"]


def vertex_model(G: np.ndarray, rhs: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> highspy.HighsLp:
    """The HiGHS model of ``max t s.t. G u + t 1 <= rhs, lo <= u <= hi, t <= 1`` (minimising
    ``-t``), columns ``(u (C,), t)``.

    Parameters
    ----------
    G : ndarray, shape (R, C)
    rhs : ndarray, shape (R,)
    lo, hi : ndarray, shape (C,)
    """
    R, C = G.shape
    inf = highspy.kHighsInf
    lp = highspy.HighsLp()
    lp.num_col_ = C + 1
    lp.num_row_ = R
    cost = np.zeros(C + 1)
    cost[C] = -1.0                                   # minimise -t
    lp.col_cost_ = cost
    lp.col_lower_ = np.append(lo, -inf)
    lp.col_upper_ = np.append(hi, 1.0)
    lp.row_lower_ = np.full(R, -inf)
    lp.row_upper_ = rhs
    At = np.vstack([G.T, np.ones((1, R))])
    col, row = np.nonzero(At)
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = np.searchsorted(col, np.arange(C + 2)).astype(np.int32)
    lp.a_matrix_.index_ = row.astype(np.int32)
    lp.a_matrix_.value_ = At[col, row]
    return lp


def dual_bounds(G: np.ndarray, rhs: np.ndarray, lo: np.ndarray, hi: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Weak-duality upper bounds on ``max t s.t. G u + t <= rhs[:, v], lo <= u <= hi`` from each
    row of ``Y`` (``>= 0``), for each right-hand side ``v``.

    Each ``y`` is clipped at 0 and scaled to ``Σ y = 1`` (``+inf`` when it is 0); its bound is
    ``y . rhs + Σ_c max(-c_c lo_c, -c_c hi_c)`` with ``c = G^T y``, plus an allowance for the
    float64 rounding of the sums (``1e-12`` of their absolute size).

    Parameters
    ----------
    G : ndarray, shape (R, C)
    rhs : ndarray, shape (R,) or (R, V)
    lo, hi : ndarray, shape (C,)
    Y : ndarray, shape (K, R)

    Returns
    -------
    ndarray, shape (K,) or (K, V)
    """
    store = DualStore(G, lo, hi)
    R2 = rhs if rhs.ndim == 2 else rhs[:, None]
    b = np.full((len(np.atleast_2d(Y)), R2.shape[1]), np.inf)
    ok = []
    for a, y in enumerate(np.atleast_2d(np.asarray(Y, float))):
        parts = store.parts(y)
        if parts is not None:
            store.add(parts)                         # put first: the store holds them newest first
            ok.insert(0, a)
    if ok:
        b[ok] = store.bounds(R2)
    return b if rhs.ndim == 2 else b[:, 0]


def dual_bound(G: np.ndarray, rhs: np.ndarray, lo: np.ndarray, hi: np.ndarray, y: np.ndarray) -> float:
    """:func:`dual_bounds` of one ``y`` (shape ``(R,)``) and one ``rhs`` (shape ``(R,)``)."""
    return float(dual_bounds(G, np.asarray(rhs, float), lo, hi, np.asarray(y, float)[None])[0])


class DualStore:
    """Dual points ``y >= 0`` (``Σ y = 1``) of one row structure ``(G, lo, hi)``, best first, each
    with the parts of its weak-duality bound that do not depend on the right-hand side.

    The bound of ``y`` at ``rhs`` is ``y . rhs + Σ_c max(-c_c lo_c, -c_c hi_c)`` (``c = G^T y``) plus
    ``1e-12`` of the sums' absolute size (the allowance for their float64 rounding); the box term
    and the absolute size of ``c``'s terms are computed once per ``y``. They are kept stacked
    (``Y (K, R)``, ``box (K,)``, ``size (K,)``), so that all bounds are two products.
    """

    def __init__(self, G: np.ndarray, lo: np.ndarray, hi: np.ndarray):
        self.G, self.lo, self.hi = G, lo, hi
        self.reach = np.abs(G) @ np.maximum(np.abs(lo), np.abs(hi))   # (R,): |G| max(|lo|, |hi|)
        self.Y = np.zeros((0, G.shape[0]))   # normalised duals, best first
        self.box = np.zeros(0)               # Σ_c max(-c lo, -c hi) per dual
        self.size = np.zeros(0)              # the rhs-free part of the rounding allowance per dual

    def __len__(self) -> int:
        return len(self.Y)

    def parts(self, y: np.ndarray) -> tuple | None:
        """``y`` clipped at 0 and normalised, its box term and the rhs-free part of its rounding
        allowance; ``None`` when its sum is not positive and finite."""
        y = np.maximum(np.asarray(y, float), 0.0)
        s = y.sum()
        if not (np.isfinite(s) and s > 0):
            return None
        y = y / s
        c = y @ self.G
        box = np.maximum(-c * self.lo, -c * self.hi)
        return y, box.sum(), np.abs(box).sum() + y @ self.reach

    @staticmethod
    def bound(parts: tuple, rhs: np.ndarray) -> float:
        """The bound of one dual's :meth:`parts` at one right-hand side ``rhs (R,)``."""
        y, box, size = parts
        return float(y @ rhs + box + 1e-12 * (y @ np.abs(rhs) + size))

    def add(self, parts: tuple, keep: int | None = None):
        """Put a dual's :meth:`parts` first, keeping at most ``keep``."""
        y, box, size = parts
        self.Y = np.concatenate([y[None], self.Y])[:keep]
        self.box = np.concatenate([[box], self.box])[:keep]
        self.size = np.concatenate([[size], self.size])[:keep]

    def promote(self, a: int):
        """Move the ``a``-th dual to the front (the most recently useful first)."""
        if a:
            idx = np.r_[a, 0:a, a + 1:len(self.Y)]
            self.Y, self.box, self.size = self.Y[idx], self.box[idx], self.size[idx]

    def bounds(self, rhs: np.ndarray) -> np.ndarray:
        """The bounds of every kept dual at each column of ``rhs (R, V)``, shape ``(K, V)``."""
        lin = self.Y @ rhs
        size = self.Y @ np.abs(rhs) + self.size[:, None]
        return lin + self.box[:, None] + 1e-12 * size


class WitnessStore:
    """Input sequences ``u ∈ box(U)^L`` of unrefuted LPs of one row structure, latest first, each
    with ``G u`` (stacked, shape ``(P, R)``).

    An LP whose right-hand side ``rhs`` keeps ``min_r (rhs_r - (G u)_r) >= -tol / 2`` at a kept
    ``u`` has ``t* >= -tol / 2``: no dual bound of it falls below ``-tol``, so it cannot refute
    and is not solved (the result is that of solving it).
    """

    def __init__(self, G: np.ndarray):
        self.G = G
        self.Gu = np.zeros((0, G.shape[0]))

    def add(self, u: np.ndarray, keep: int):
        self.Gu = np.concatenate([(self.G @ u)[None], self.Gu])[:keep]

    def shown(self, rhs: np.ndarray, tol: float) -> np.ndarray:
        """Which columns of ``rhs (R, V)`` a kept input sequence shows cannot be refuted, ``(V,)``."""
        if not len(self.Gu):
            return np.zeros(rhs.shape[1], dtype=bool)
        t = np.min(rhs[None, :, :] - self.Gu[:, :, None], axis=1)               # (P, V)
        return (t >= -0.5 * tol).any(axis=0)


class ShapeRows:
    """The vertex LPs' rows of one pair shape for every horizon, from block-Toeplitz tables.

    ``x(l)`` depends on ``u(t)`` through ``A^{l-1-t} B`` (``t < l``), so the rows of step ``l``
    against facets ``H`` are ``[H A^{l-1} B, ..., H B]`` on ``u(0..l-1)``: built once per shape
    for ``S`` (every step) and ``P_j`` (the last step), per horizon on first use, with the
    horizon's input box, its :class:`DualStore` and its :class:`WitnessStore`.

    Parameters
    ----------
    HS, Hj : ndarray, shapes (f_S, n), (f_j, n)
        Unit facet normals of ``S ⊖ W`` and ``P_j ⊖ W``.
    AtB : ndarray, shape (L_max, n, m)      ``A^t B``
    Apow : ndarray, shape (L_max + 1, n, n) ``A^l``
    ulo, uhi : ndarray, shape (m,)          ``box(U)``
    """

    def __init__(self, HS, Hj, AtB, Apow, ulo, uhi):
        self.fS, self.fj, self.m = HS.shape[0], Hj.shape[0], AtB.shape[2]
        self.BS = np.einsum("fn,tnm->tfm", HS, AtB)            # (L_max, f_S, m): H_S A^t B
        self.Bj = np.einsum("fn,tnm->tfm", Hj, AtB)
        self.MS = np.einsum("fn,lnk->lfk", HS, Apow)           # (L_max + 1, f_S, n): H_S A^l
        self.Mj = np.einsum("fn,lnk->lfk", Hj, Apow)
        self.ulo, self.uhi = ulo, uhi
        umax = np.maximum(np.abs(ulo), np.abs(uhi))
        # the reach of step l's rows with any inputs, Σ_{t<l} |H A^t B| max(|lo|, |hi|): (L_max, f) for l = 1 .. L_max
        self.reachS = np.cumsum(np.abs(self.BS) @ umax, axis=0)
        self.reachj = np.cumsum(np.abs(self.Bj) @ umax, axis=0)
        self._at: dict = {}

    def at(self, L: int) -> "_Horizon":
        hit = self._at.get(L)
        if hit is None:
            hit = self._at[L] = _Horizon(self, L)
        return hit

    def pair(self, gS: np.ndarray, gj: np.ndarray, V: np.ndarray, L_top: int) -> "_PairRhs":
        """The right-hand sides of one pair's vertex LPs (offsets ``gS``, ``gj``, vertices ``V (nv, n)``)
        up to horizon ``L_top``."""
        return _PairRhs(self, gS, gj, V, L_top)


class _PairRhs:
    """One pair's vertex-LP right-hand sides ``g - M v``, for every vertex at once: the ``S`` rows of
    steps ``1 .. L_top - 1`` (``XS (L_top - 1, f_S, nv)``) once, the ``P_j`` rows per horizon, and
    each vertex's score at a horizon: the least of its rows' ``rhs + reach`` (how far the
    vertex's reach with any inputs misses them), from a running minimum over the steps."""

    def __init__(self, rows: ShapeRows, gS, gj, V, L_top: int):
        self.rows, self.gj, self.VT = rows, gj, V.T
        self.XS = gS[None, :, None] - rows.MS[1:L_top] @ self.VT
        reach = np.min(self.XS + rows.reachS[:L_top - 1, :, None], axis=1)            # (L_top - 1, nv)
        self.smin = np.minimum.accumulate(reach, axis=0) if len(reach) else reach

    def at(self, L: int, count: int | None) -> tuple[np.ndarray, np.ndarray]:
        """Horizon ``L``: the ``count`` vertices of least score (least first) and their right-hand
        sides, ``(order (V,), rhs (R, V))``, rows as in :class:`_Horizon`."""
        rows = self.rows
        Xj = self.gj[:, None] - rows.Mj[L] @ self.VT                                    # (f_j, nv)
        score = np.min(Xj + rows.reachj[L - 1][:, None], axis=0)
        if L >= 2:
            score = np.minimum(score, self.smin[L - 2])
        order = np.argsort(score, kind="stable")[:count]
        XS = self.XS[:L - 1][:, :, order]
        return order, np.concatenate([XS.reshape(-1, len(order)), Xj[:, order]])


class _Horizon:
    """One horizon's rows ``G (R, L m)`` (the rhs of a vertex: :class:`_PairRhs`), input box,
    refuting duals and witnessing inputs."""

    def __init__(self, rows: ShapeRows, L: int):
        fS, m = rows.fS, rows.m
        G = np.zeros((L - 1, fS, L, m))
        for ell in range(1, L):                               # block row of step ell
            G[ell - 1, :, :ell] = np.moveaxis(rows.BS[ell - 1::-1], 0, 1)
        last = np.moveaxis(rows.Bj[L - 1::-1], 0, 1)           # (f_j, L, m): u(t) -> x(L)
        self.G = np.concatenate([G.reshape((L - 1) * fS, L * m), last.reshape(rows.fj, L * m)])
        self.lo, self.hi = np.tile(rows.ulo, L), np.tile(rows.uhi, L)
        self.duals = DualStore(self.G, self.lo, self.hi)
        self.witnesses = WitnessStore(self.G)
        self.idx = np.arange(self.G.shape[0], dtype=np.int32)
        self.neg_inf = np.full(self.G.shape[0], -highspy.kHighsInf)


def shape_key(HS: np.ndarray, Hj: np.ndarray, HS_bytes: bytes | None = None, Hj_bytes: bytes | None = None) -> bytes:
    """What fixes a pair's vertex LPs up to their right-hand sides: the facet normals of
    ``S ⊖ W`` and ``P_j ⊖ W`` (bytes; ``*_bytes``: their ``tobytes()``, if known)."""
    return (np.asarray(HS.shape, np.int64).tobytes() + (HS.tobytes() if HS_bytes is None else HS_bytes)
            + (Hj.tobytes() if Hj_bytes is None else Hj_bytes))


def screen_pairs(jobs: list, const: tuple) -> list:
    """(VL) on the horizons of some pairs; a pure function of its arguments (module level, so
    that a helper process can run it).

    A dual point that refuted one vertex LP is tried first on the next LPs with the same rows
    (same pair shape and horizon; only the right-hand side moves with the pair and the vertex):
    its weak-duality bound on the instance's own data below ``-tol`` drops the horizon with no
    HiGHS solve, on the same evidence as a solved one. Likewise the inputs HiGHS found for an
    unrefuted LP are tried on the next vertices with the same rows (:class:`WitnessStore`).

    Parameters
    ----------
    jobs : list of ``(k, H_S, g_S, H_j, g_j, V_i, Ls)``
        A pair's index, the unit H-reps of ``S ⊖ W`` and ``P_j ⊖ W``, the source vertices
        ``(n_v, n)`` and its kept horizons in increasing order.
    const : tuple
        ``(A^t B (L_max, n, m), A^l (L_max + 1, n, n), box(U) lo, hi, tol per L, survivors,
        max_vertices, refuting duals kept per row structure)`` (read in the calling process, so
        that a helper process uses the caller's settings).

    Returns
    -------
    list of ``(k, dropped horizons, LPs solved, horizons dropped by a reused dual, LPs skipped)``
    """
    AtB, Apow, ulo, uhi, tols, survivors, max_vertices, certificates = const
    solvers: dict = {}                                 # L -> [Highs, the _Horizon it holds]
    out = []
    shapes: dict = {}                                  # shape key -> ShapeRows
    for k, HS, gS, Hj, gj, Vi, Ls in jobs:
        key = shape_key(HS, Hj)
        rows = shapes.get(key)
        if rows is None:
            rows = shapes[key] = ShapeRows(HS, Hj, AtB, Apow, ulo, uhi)
        dropped, lps, reused, passed, witnessed = [], 0, 0, 0, 0
        pair = rows.pair(gS, gj, Vi, Ls[-1]) if Ls else None
        for L in Ls:
            if passed >= survivors:
                break
            hz = rows.at(L)
            # the vertices whose unconstrained reach misses the rows most, first
            order, rhs = pair.at(L, max_vertices)
            tol = float(tols[L])
            if certificates and len(hz.duals):
                hit = np.flatnonzero((hz.duals.bounds(rhs) < -tol).any(axis=1))
                if hit.size:
                    hz.duals.promote(int(hit[0]))
                    dropped.append(L)
                    reused += 1
                    continue
            shown = hz.witnesses.shown(rhs, tol) if certificates else np.zeros(len(order), bool)
            slot = solvers.get(L)
            if slot is None:
                slot = solvers[L] = [new_highs(), None]
            h = slot[0]
            for a in range(len(order)):
                if shown[a]:
                    witnessed += 1
                    continue
                if slot[1] is not hz:
                    h.clearSolver()
                    h.passModel(vertex_model(hz.G, rhs[:, a], hz.lo, hz.hi))
                    slot[1] = hz
                else:
                    h.changeRowsBounds(len(hz.idx), hz.idx, hz.neg_inf, rhs[:, a])
                h.run()
                lps += 1
                if h.getModelStatus() != highspy.HighsModelStatus.kOptimal:
                    continue
                sol = h.getSolution()
                parts = hz.duals.parts(-np.asarray(sol.row_dual))
                if parts is not None and hz.duals.bound(parts, rhs[:, a]) < -tol:
                    dropped.append(L)
                    if certificates:
                        hz.duals.add(parts, keep=certificates)
                    break
                if certificates:
                    hz.witnesses.add(np.clip(np.asarray(sol.col_value)[:-1], hz.lo, hz.hi), certificates)
            else:
                passed += 1
        out.append((k, dropped, lps, reused, witnessed))
    return out
