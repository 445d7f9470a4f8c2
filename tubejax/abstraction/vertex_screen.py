"""The screening kernel of the vertex-LP rule (:mod:`tubejax.abstraction.vertex_lp`): one pair's
vertex LPs, with the rows, refuting duals and witnessing inputs kept per row structure.

A vertex LP of horizon ``L`` is ``max t  s.t.  G u + t 1 <= g - M v,  u ∈ box(U)^L,  t <= 1``: the
open-loop LP of one vertex, ``G`` and ``M`` read off its declaration (:class:`StepTables`). They depend
only on the facet normals of ``S ⊖ W`` and ``P_j ⊖ W`` (the pair's *shape*) and ``L``; ``g`` on where
the pair lies, ``v`` on the vertex. Pairs arrive sorted by shape, so what depends on the shape and ``L``
only (:class:`ShapeRows`), the rhs-free parts of dual bounds (:class:`DualStore`) and the rows' values
at witnessing inputs (:class:`WitnessStore`) are computed once per run of like pairs; what a bound or
witness decides is computed from the instance's own right-hand sides.
"""

from __future__ import annotations

import highspy
import numpy as np

from ..lp.declarations.openloop_families import step_rows
from ..lp.declarations.tube_lp import TubeLP
from ..lp.engines.highs import new_highs, pass_margin_lp

__all__ = ["StepTables", "ShapeRows", "DualStore", "WitnessStore", "screen_pairs", "dual_bounds", "dual_bound",
           "vertex_margin_lp"]


def vertex_margin_lp(G: np.ndarray, rhs: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> TubeLP:
    """The vertex LP ``max t s.t. G u + t 1 <= rhs, lo <= u <= hi, t <= 1`` (``G (R, C)``, ``rhs (R,)``,
    ``lo, hi (C,)``) as a margin-form record, columns ``(u, t)``, for
    :func:`~tubejax.lp.engines.highs.pass_margin_lp`."""
    return TubeLP(G, rhs, np.zeros(G.shape[0], np.int8), np.zeros((0, G.shape[1])), np.zeros(0), lo, hi, 1.0, None)


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
            store.add(parts)                         # slots in the order added
            ok.append(a)
    if ok:
        b[ok] = store.bounds(R2)
    return b if rhs.ndim == 2 else b[:, 0]


def dual_bound(G: np.ndarray, rhs: np.ndarray, lo: np.ndarray, hi: np.ndarray, y: np.ndarray) -> float:
    """:func:`dual_bounds` of one ``y`` (shape ``(R,)``) and one ``rhs`` (shape ``(R,)``)."""
    return float(dual_bounds(G, np.asarray(rhs, float), lo, hi, np.asarray(y, float)[None])[0])


class DualStore:
    """Dual points ``y >= 0`` (``Σ y = 1``) of one row structure ``(G, lo, hi)``, most recently useful
    first, each with the rhs-free parts of its weak-duality bound (:func:`dual_bounds`), so all bounds
    are two products. :attr:`order` lists slots, :attr:`ids` each slot's dual's serial number."""

    def __init__(self, G: np.ndarray, lo: np.ndarray, hi: np.ndarray):
        self.G, self.lo, self.hi = G, lo, hi
        self.reach = np.abs(G) @ np.maximum(np.abs(lo), np.abs(hi))   # (R,): |G| max(|lo|, |hi|)
        self.Y = np.zeros((0, G.shape[0]))   # normalised duals, by slot
        self.box = np.zeros(0)               # Σ_c max(-c lo, -c hi) per slot
        self.size = np.zeros(0)              # the rhs-free part of the rounding allowance per slot
        self.order: list = []                # slots, the most recently useful first
        self.ids: list = []                  # per slot: the serial number of its dual
        self._next = 0

    def __len__(self) -> int:
        return len(self.order)

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

    def add(self, parts: tuple, keep: int | None = None) -> int:
        """Put a dual's :meth:`parts` first, keeping at most ``keep`` (the last one's slot is
        reused); returns its slot."""
        y, box, size = parts
        if keep is not None and len(self.order) >= keep > 0:
            slot = self.order.pop()
            self.Y[slot], self.box[slot], self.size[slot] = y, box, size
            self.ids[slot] = self._next
        else:
            slot = len(self.Y)
            self.Y = np.concatenate([self.Y, y[None]])
            self.box = np.append(self.box, box)
            self.size = np.append(self.size, size)
            self.ids.append(self._next)
        self.order.insert(0, slot)
        self._next += 1
        return slot

    def first_of(self, ids: set) -> int | None:
        """The place in :attr:`order` of the first kept dual whose serial number is in ``ids``."""
        return next((a for a, slot in enumerate(self.order) if self.ids[slot] in ids), None)

    def promote(self, a: int):
        """Move the ``a``-th dual of :attr:`order` to the front (the most recently useful first)."""
        if a:
            self.order.insert(0, self.order.pop(a))

    def bounds(self, rhs: np.ndarray, slot: int | None = None) -> np.ndarray:
        """The bounds of the dual in every slot (or in ``slot`` alone: ``K = 1``) at each column of
        ``rhs (R, V)``, shape ``(K, V)``; of a stack ``rhs (A, R, V)``, shape ``(A, K, V)``."""
        at = slice(None) if slot is None else slice(slot, slot + 1)
        Y = self.Y[at]
        lin = Y @ rhs
        size = Y @ np.abs(rhs) + self.size[at, None]
        return lin + self.box[at, None] + 1e-12 * size


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


class StepTables:
    """The rows of every step ``1 .. L_max`` over a set of facets ``H``, read off the open-loop LP's
    declaration (:func:`~tubejax.lp.declarations.openloop_families.step_rows`) once over ``H = I`` (the
    rows are linear in ``H``) and applied to each facet array once.

    Parameters
    ----------
    A, B : ndarray, shapes (n, n), (n, m)
    L_max : int
    ulo, uhi : ndarray, shape (m,)          ``box(U)``
    """

    def __init__(self, A, B, L_max: int, ulo, uhi):
        self.m, self.ulo, self.uhi = B.shape[1], ulo, uhi
        self.umax = np.maximum(np.abs(ulo), np.abs(uhi))
        self.C, self.M = step_rows(np.eye(A.shape[0]), A, B, L_max)   # (L_max, n, L_max, m), (L_max, n, n)
        self._of: dict = {}

    def of(self, H: np.ndarray) -> tuple:
        """``(C, M, reach)`` of the facets ``H (f, n)``: ``C (L_max, f, L_max, m)`` the coefficient of
        ``u(t)`` in step ``l``'s rows, ``M (L_max + 1, f, n)`` = ``H A^l`` (``l = 0 .. L_max``) and
        ``reach (L_max, f)`` = ``Σ_{t<l} |H A^t B| max(|lo|, |hi|)``, the reach of step ``l``'s rows
        with any inputs (``H A^t B`` is ``u(0)``'s coefficient at step ``t + 1``)."""
        key = np.asarray(H.shape, np.int64).tobytes() + H.tobytes()
        hit = self._of.get(key)
        if hit is None:
            C = np.einsum("fn,lntj->lftj", H, self.C)
            hit = self._of[key] = (C, np.concatenate([H[None], np.einsum("fn,lnk->lfk", H, self.M)]),
                                   np.cumsum(np.abs(C[:, :, 0]) @ self.umax, axis=0))
        return hit


class ShapeRows:
    """The vertex LPs' rows of one pair shape (unit normals ``HS (f_S, n)`` of ``S ⊖ W``, ``Hj (f_j, n)``
    of ``P_j ⊖ W``) for every horizon ``L``: the ``S`` rows of steps ``1 .. L-1`` and the ``P_j`` rows of
    step ``L`` on ``u(0..L-1)``, sliced from ``tables`` on first use (:class:`_Horizon`)."""

    def __init__(self, HS, Hj, tables: StepTables):
        self.fS, self.fj, self.m = HS.shape[0], Hj.shape[0], tables.m
        self.CS, self.MS, self.reachS = tables.of(HS)
        self.Cj, self.Mj, self.reachj = tables.of(Hj)
        self.ulo, self.uhi = tables.ulo, tables.uhi
        self._at: dict = {}

    def at(self, L: int) -> "_Horizon":
        hit = self._at.get(L)
        if hit is None:
            hit = self._at[L] = _Horizon(self, L)
        return hit

    def pairs(self, gS: np.ndarray, gj: np.ndarray, V: np.ndarray, L_top: int) -> "_PairsRhs":
        """The right-hand sides of the vertex LPs of ``P`` pairs of this shape (offsets ``gS (P, f_S)``,
        ``gj (P, f_j)``, vertices ``V (P, nv, n)``) up to horizon ``L_top``."""
        return _PairsRhs(self, gS, gj, V, L_top)


class _PairsRhs:
    """The vertex-LP right-hand sides ``g - M v`` of ``P`` pairs of one shape, for every vertex at
    once: the ``S`` rows of steps ``1 .. L_top - 1`` (``XS (P, L_top - 1, f_S, nv)``) once, the
    ``P_j`` rows per horizon, and each vertex's score at a horizon: the least of its rows'
    ``rhs + reach`` (how far the vertex's reach with any inputs misses them), from a running
    minimum over the steps."""

    def __init__(self, rows: ShapeRows, gS, gj, V, L_top: int):
        self.rows, self.gj, self.VT = rows, gj, np.swapaxes(V, 1, 2)                   # VT (P, n, nv)
        self.XS = gS[:, None, :, None] - rows.MS[None, 1:L_top] @ self.VT[:, None]     # (P, L_top - 1, f_S, nv)
        reach = np.min(self.XS + rows.reachS[None, :L_top - 1, :, None], axis=2)       # (P, L_top - 1, nv)
        self.smin = np.minimum.accumulate(reach, axis=1) if reach.shape[1] else reach

    def at(self, L: int, count: int | None, sel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Horizon ``L`` of the pairs ``sel (A,)``: per pair the ``count`` vertices of least score (least
        first) and their right-hand sides, ``(order (A, c), rhs (A, R, c))``, rows as in
        :class:`_Horizon`."""
        rows = self.rows
        Xj = self.gj[sel][:, :, None] - rows.Mj[L] @ self.VT[sel]                       # (A, f_j, nv)
        score = np.min(Xj + rows.reachj[L - 1][None, :, None], axis=1)                  # (A, nv)
        if L >= 2:
            score = np.minimum(score, self.smin[sel, L - 2])
        order = np.argsort(score, axis=1, kind="stable")[:, :count]                     # (A, c)
        XS = np.take_along_axis(self.XS[sel, :L - 1], order[:, None, None, :], axis=3)  # (A, L - 1, f_S, c)
        Xj = np.take_along_axis(Xj, order[:, None, :], axis=2)
        return order, np.concatenate([XS.reshape(len(sel), -1, order.shape[1]), Xj], axis=1)


class _Horizon:
    """One horizon's rows ``G (R, L m)`` (a vertex's rhs: :class:`_PairsRhs`), box, duals and witnesses."""

    def __init__(self, rows: ShapeRows, L: int):
        fS, m = rows.fS, rows.m
        self.G = np.concatenate([rows.CS[:L - 1, :, :L].reshape((L - 1) * fS, L * m),
                                 rows.Cj[L - 1, :, :L].reshape(rows.fj, L * m)])
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
    """(VL) on the horizons of some pairs; a pure module-level function, so a helper process can run it.

    A dual that refuted one vertex LP is tried first on the next LPs with the same rows: its
    weak-duality bound on the instance's own data below ``-tol`` drops the horizon, on the same evidence
    as a solve; likewise kept inputs (:class:`WitnessStore`). Pairs of one shape are screened together,
    with the outcome of screening them one after the other.

    Parameters
    ----------
    jobs : list of ``(k, H_S, g_S, H_j, g_j, V_i, Ls)``
        A pair's index, the unit H-reps of ``S ⊖ W`` and ``P_j ⊖ W``, the source vertices
        ``(n_v, n)`` and its kept horizons in increasing order.
    const : tuple
        ``(A (n, n), B (n, m), box(U) lo, hi, tol per L (L_max + 1,), survivors, max_vertices,
        refuting duals kept per row structure)`` (the caller's settings, also in a helper process).

    Returns
    -------
    list of ``(k, dropped horizons, LPs solved, horizons dropped by a reused dual, LPs skipped)``
    """
    A, B, ulo, uhi, tols, survivors, max_vertices, certificates = const
    tables = StepTables(A, B, len(tols) - 1, ulo, uhi)
    solvers: dict = {}                                 # L -> [Highs, the _Horizon it holds]
    shapes: dict = {}                                  # shape key -> ShapeRows
    out = [None] * len(jobs)
    runs: list = []                                    # [(shape key, vertex count), positions]
    for pos, (_, HS, _, Hj, _, Vi, _) in enumerate(jobs):
        key = (shape_key(HS, Hj), len(Vi))
        if runs and runs[-1][0] == key:
            runs[-1][1].append(pos)
        else:
            runs.append((key, [pos]))
    for key, run in runs:
        first = jobs[run[0]]
        rows = shapes.get(key[0])
        if rows is None:
            rows = shapes[key[0]] = ShapeRows(first[1], first[3], tables)
        tally = [[[], 0, 0, 0] for _ in run]           # per pair: dropped, LPs, reused, witnessed
        passed = np.zeros(len(run), np.int64)
        has = np.zeros((len(run), len(tols)), bool)    # has[a, L]: horizon L is kept for pair a
        for a, p in enumerate(run):
            has[a, jobs[p][6]] = True
        todo = np.flatnonzero(has.any(axis=0)).tolist()
        if todo:
            rhs_of = rows.pairs(np.stack([jobs[p][2] for p in run]), np.stack([jobs[p][4] for p in run]),
                                np.stack([jobs[p][5] for p in run]), todo[-1])
        for L in todo:
            act = np.flatnonzero(has[:, L] & (passed < survivors))
            if not act.size:
                continue
            hz = rows.at(L)
            tol = float(tols[L])
            order, rhs = rhs_of.at(L, max_vertices, act)                               # (A, c), (A, R, c)
            refuters = [set() for _ in act]            # serial numbers of kept duals refuting each pair
            if certificates and len(hz.duals):
                hits = (hz.duals.bounds(rhs) < -tol).any(axis=2)                       # (A, K)
                for a, ks in zip(*np.nonzero(hits)):
                    refuters[a].add(hz.duals.ids[ks])
            for a, pair in enumerate(act.tolist()):
                rec = tally[pair]
                if refuters[a]:
                    kept = hz.duals.first_of(refuters[a])
                    if kept is not None:               # a dual still kept refutes it: dropped, no LP
                        hz.duals.promote(kept)
                        rec[0].append(L)
                        rec[2] += 1
                        continue
                refuted, lps, witnessed = _solve_vertices(hz, rhs[a], solvers, L, tol, certificates)
                rec[1] += lps
                rec[3] += witnessed
                if refuted is None:
                    passed[pair] += 1
                    continue
                rec[0].append(L)
                if certificates and a + 1 < len(act):  # the new dual on the pairs still to come
                    slot = hz.duals.order[0]
                    later = (hz.duals.bounds(rhs[a + 1:], slot)[:, 0] < -tol).any(axis=1)
                    for b in np.flatnonzero(later).tolist():
                        refuters[a + 1 + b].add(hz.duals.ids[slot])
        for pos, rec in zip(run, tally):
            out[pos] = (jobs[pos][0], rec[0], rec[1], rec[2], rec[3])
    return out


def _solve_vertices(hz: "_Horizon", rhs: np.ndarray, solvers: dict, L: int, tol: float, certificates: int):
    """Solve one instance's vertex LPs (right-hand sides ``rhs (R, c)``, in that order) until one is
    refuted; returns ``(the refuting dual's parts or None, LPs solved, LPs a witness skipped)``.
    A refuting dual is put first in ``hz.duals``, and the inputs of an unrefuted LP in
    ``hz.witnesses`` (with ``certificates``, the number kept)."""
    shown = hz.witnesses.shown(rhs, tol) if certificates else np.zeros(rhs.shape[1], bool)
    slot = solvers.get(L)
    if slot is None:
        slot = solvers[L] = [new_highs(), None]
    h = slot[0]
    lps = witnessed = 0
    for a in range(rhs.shape[1]):
        if shown[a]:
            witnessed += 1
            continue
        if slot[1] is not hz:
            h.clearSolver()
            pass_margin_lp(h, vertex_margin_lp(hz.G, rhs[:, a], hz.lo, hz.hi))
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
            if certificates:
                hz.duals.add(parts, keep=certificates)
            return parts, lps, witnessed
        if certificates:
            hz.witnesses.add(np.clip(np.asarray(sol.col_value)[:-1], hz.lo, hz.hi), certificates)
    return None, lps, witnessed
