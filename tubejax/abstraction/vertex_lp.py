"""Pruning by one small LP per vertex: can the vertex reach ``P_j ⊖ W`` while staying in ``S ⊖ W``?

(VL) Along Lemma 1's ``w = 0`` trajectory of a vertex ``v`` of ``P_i`` (:mod:`tubejax.abstraction.pruning`),
the inputs ``u(0..L-1)`` lie in ``U`` and the states ``x(l) = A^l v + Σ_{t<l} A^{l-1-t} B u(t)``
satisfy ``x(l) ∈ Q_l ⊖ W ⊆ S ⊖ W`` for ``l = 1 .. L-1`` (C2, C4) and ``x(L) ∈ P_j ⊖ W`` (C3).
So if, for one vertex, no input sequence in ``U`` keeps these linear constraints, ``(i, j, L)``
is infeasible. :mod:`tubejax.abstraction.safe_reach` tests the same condition with boxes; here it is
decided by an LP in the inputs only (``L m`` variables), in margin form::

    max t   s.t.   G_v u + t 1 <= g_v,   u ∈ box(U)^L,   t <= 1,

with unit state-space rows ``G_v`` (the facets of ``S ⊖ W`` at ``l < L``, of ``P_j ⊖ W`` at
``l = L``; ``S = P_ij`` in the free case, ``P_i`` in the obstacle case). ``U`` must be a box
(else the rule is skipped), so that ``box(U) = U``.

**Soundness.** HiGHS only proposes the dual point: for any ``y >= 0`` with ``Σ y = 1``, weak
duality gives ``t* <= y . g_v + Σ_c max(-c_c lo_c, -c_c hi_c)`` with ``c = G_v^T y`` (the
``box(U)`` bounds ``lo, hi``), which is evaluated in float64 here. A horizon is dropped only
when that bound is below ``-tol_L`` (the pruning tolerance of :mod:`tubejax.abstraction.pruning`, far above
the rounding of the evaluation and the ``1e-9`` slack a verified tube may have), so no
instance that could become an edge is ever dropped (**vertex_lp_infeasible**).

The constraint matrix does not depend on the vertex (only ``g_v`` does): one HiGHS model per
instance, re-solved from the previous basis for each vertex (a hot start), vertices in
decreasing order of a cheap score (how far the vertex's reach box misses ``P_j ⊖ W``), and
the first infeasible vertex ends the instance. The rows ``G`` depend only on the pair's shape
(its facet normals) and ``L``; the vertex and the pair's position enter through the right-hand
side. So a dual point that refuted one LP is tried first on the next LPs with the same rows
(pairs are screened sorted by shape): if the weak-duality bound of the instance's own data is
below ``-tol_L``, the horizon is dropped on exactly the evidence a solve would give, with no
solve.
"""

from __future__ import annotations

import highspy
import numpy as np

from ..model.geometry import support
from .pruning import ReachTables, _padded_vertices
from ..model.system import LinearSystem
from .translations import TranslationClasses
from ..model.workspace.decomposition import CellDecomposition
from ..lp.solvers.highs import new_highs

__all__ = ["vertex_lp_keep", "VERTEX_LP_MIN_DIM"]

#: The rule runs by default in state dimensions of at least this (in 2-D the cheap tests are
#: already exact for most instances and the LPs cost more than they save).
VERTEX_LP_MIN_DIM = 3


def _shrunk_hrep(hrep, W) -> tuple[np.ndarray, np.ndarray]:
    """``P ⊖ W = {x : H x <= h - σ_W(H)}`` (exact for the support function), unit rows, for
    ``P = {x : H x <= h}`` given as ``hrep = (H (f, n), h (f,))``."""
    H, h = hrep
    nrm = np.linalg.norm(H, axis=1)
    H, h = H / nrm[:, None], h / nrm
    return H, h - support(W, H)


def _input_blocks(system: LinearSystem, L_max: int) -> np.ndarray:
    """``A^t B`` for ``t = 0 .. L_max - 1``, shape ``(L_max, n, m)``."""
    out, M = [], system.B.copy()
    for _ in range(L_max):
        out.append(M)
        M = system.A @ M
    return np.array(out)


class _PairRows:
    """The margin LP's rows of one pair for every horizon, from block-Toeplitz tables.

    ``x(l)`` depends on ``u(t)`` through ``A^{l-1-t} B`` (``t < l``), so the rows of step ``l``
    against facets ``H`` are ``[H A^{l-1} B, ..., H B]`` on ``u(0..l-1)``: computed once per pair
    for ``S`` (every step) and ``P_j`` (the last step) and sliced per horizon.
    """

    def __init__(self, HS, gS, Hj, gj, AtB: np.ndarray, Apow: np.ndarray):
        self.HS, self.gS, self.Hj, self.gj = HS, gS, Hj, gj
        self.BS = np.einsum("fn,tnm->tfm", HS, AtB)            # (L_max, f_S, m): H_S A^t B
        self.Bj = np.einsum("fn,tnm->tfm", Hj, AtB)
        self.MS = np.einsum("fn,lnk->lfk", HS, Apow)           # (L_max + 1, f_S, n): H_S A^l
        self.Mj = np.einsum("fn,lnk->lfk", Hj, Apow)

    def rows(self, L: int):
        """``G (R, L m)``, the vertex-free rhs ``g (R,)`` and the state map ``M (R, n)`` (the rhs
        of a vertex ``v`` is ``g - M v``) of horizon ``L``."""
        fS, m = self.HS.shape[0], self.BS.shape[2]
        fj = self.Hj.shape[0]
        G = np.zeros((L - 1, fS, L, m))
        for ell in range(1, L):                               # block row of step ell
            G[ell - 1, :, :ell] = np.moveaxis(self.BS[ell - 1::-1], 0, 1)
        last = np.moveaxis(self.Bj[L - 1::-1], 0, 1)           # (f_j, L, m): u(t) -> x(L)
        G = np.concatenate([G.reshape((L - 1) * fS, L * m), last.reshape(fj, L * m)])
        g = np.concatenate([np.tile(self.gS, L - 1), self.gj])
        M = np.concatenate([self.MS[1:L].reshape((L - 1) * fS, -1), self.Mj[L]])
        return G, g, M


def _model(G: np.ndarray, rhs: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> highspy.HighsLp:
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
    Y = np.maximum(np.atleast_2d(np.asarray(Y, float)), 0.0)
    s = Y.sum(axis=1)
    ok = np.isfinite(s) & (s > 0)
    Y = Y / np.where(ok, s, 1.0)[:, None]
    c = Y @ G                                                        # (K, C)
    box = np.maximum(-c * lo, -c * hi)                               # (K, C)
    R2 = rhs if rhs.ndim == 2 else rhs[:, None]
    lin = Y @ R2                                                     # (K, V)
    size = np.abs(Y) @ np.abs(R2) + (np.abs(box).sum(axis=1) + (Y @ np.abs(G)) @ np.maximum(abs(lo), abs(hi)))[:, None]
    b = np.where(ok[:, None], lin + box.sum(axis=1)[:, None] + 1e-12 * size, np.inf)
    return b if rhs.ndim == 2 else b[:, 0]


def dual_bound(G: np.ndarray, rhs: np.ndarray, lo: np.ndarray, hi: np.ndarray, y: np.ndarray) -> float:
    """:func:`dual_bounds` of one ``y`` (shape ``(R,)``) and one ``rhs`` (shape ``(R,)``)."""
    return float(dual_bounds(G, np.asarray(rhs, float), lo, hi, np.asarray(y, float)[None])[0])


def vertex_lp_keep(decomp: CellDecomposition, system: LinearSystem, T: ReachTables, src, dst, obstacle,
                   keep: np.ndarray, min_L: int = 2, survivors: int = 2,
                   max_vertices: int | None = 4, workers=None) -> tuple[np.ndarray, int, int, int, int]:
    """Apply (VL) to the kept instances; returns ``(keep, n_pruned, n_lps, n_reused, n_witnessed)``.

    Parameters
    ----------
    src, dst : ndarray of int, shape (K,)
    obstacle : ndarray of bool, shape (K,)
    keep : ndarray of bool, shape (K, L_max)
        The instances still kept (the result is a copy with the dropped ones False).
    min_L : int
        Horizons below this are left alone (at ``L = 1`` there is no ``S`` constraint and the
        vertex test of :mod:`tubejax.abstraction.pruning` already decides the same condition).
    survivors : int
        Per pair, horizons are screened in increasing order until this many passed (every
        vertex LP feasible); the later ones are kept unscreened. Algorithm 2 solves a horizon
        only when every smaller one failed, and a pair whose vertices all reach at ``L`` is
        often an edge there: screening its later horizons would mostly be wasted.
    max_vertices : int, optional
        Solve at most this many vertex LPs per instance (the highest scores first; ``None``:
        all). Fewer only keeps more instances; measured on the 4-D ``4^4`` grid, 4 keep 99 % of
        the drops of all 16 at 2/3 of the time.
    workers : optional
        A pool with ``submit_many`` (:class:`~tubejax.lp.solvers.workers.ProcessWorkers`): the
        pairs are screened there, in chunks (same result: each pair's is a pure function of
        its data). ``None``: in this process.

    Returns
    -------
    keep : ndarray of bool, shape (K, L_max)
    n_pruned : int
        Instances dropped.
    n_lps : int
        Vertex LPs solved (each a hot start of the instance's model but the first): one pair per
        exact translation class with the same kept horizons is screened, and its result holds for
        the class (:mod:`tubejax.abstraction.translations`).
    n_reused : int
        Horizons dropped by a dual point reused from an earlier LP of the same rows, with no LP of
        their own (:func:`screen_pairs`).
    n_witnessed : int
        Vertex LPs not solved because the inputs of an earlier unrefuted LP of the same rows show
        that they cannot refute (:func:`screen_pairs`).
    """
    keep = np.array(keep, dtype=bool, copy=True)
    if not system.u_is_box or len(src) == 0:
        return keep, 0, 0, 0, 0
    L_max = keep.shape[1]
    n = decomp.dim
    W = system.W
    ulo, uhi = system.U.bounding_box()
    Apow = [np.eye(n)]
    for _ in range(L_max):
        Apow.append(system.A @ Apow[-1])
    const = (_input_blocks(system, L_max), np.array(Apow), np.asarray(ulo, float), np.asarray(uhi, float),
             np.asarray(T.tol, float), int(survivors), max_vertices, int(_CERTIFICATES))
    V = _padded_vertices(decomp)
    todo = np.flatnonzero(keep[:, min_L - 1:].any(axis=1))
    if todo.size == 0:
        return keep, 0, 0, 0, 0
    # one screen per exact translation class (tubejax.abstraction.translations: the same result), the same kept horizons
    rep = TranslationClasses(decomp, system).group(np.asarray(src)[todo], np.asarray(dst)[todo],
                                                   np.asarray(obstacle, bool)[todo], keep[todo, min_L - 1:])
    members = todo
    todo = todo[rep == np.arange(len(todo))]
    rep_of = dict(zip(members.tolist(), members[rep].tolist()))
    free = todo[~np.asarray(obstacle, bool)[todo]]
    hull_of = dict(zip(free.tolist(), decomp.pair_hull_hreps(np.asarray(src)[free], np.asarray(dst)[free])))
    jobs = []
    for k in todo.tolist():
        i, j = int(src[k]), int(dst[k])
        Ls = (np.flatnonzero(keep[k, min_L - 1:]) + min_L).tolist()
        Pi, Pj = decomp.cells[i], decomp.cells[j]
        jobs.append((k, *_shrunk_hrep(hull_of.get(k, (Pi.H, Pi.h)), W), *_shrunk_hrep((Pj.H, Pj.h), W),
                     V[i, :decomp.cells[i].n_vertices], Ls))
    results = _run(jobs, const, workers)
    lps = reused = witnessed = 0
    drops = {}
    for k, dropped, n_lps, n_reused, n_witnessed in results:
        drops[k] = dropped
        lps += n_lps
        reused += n_reused
        witnessed += n_witnessed
    pruned = 0
    for k, r in rep_of.items():
        for L in drops[r]:
            keep[k, L - 1] = False
        pruned += len(drops[r])
    return keep, pruned, lps, reused, witnessed


#: Pairs per chunk (one call of :func:`screen_pairs`, here or in a helper process): at least
#: :data:`_JOB_PAIRS` and at most 4x as many, so that there are about :data:`_JOB_CHUNKS` chunks.
#: Pairs of one shape follow each other (sorted), so a chunk's refuting duals are reused across
#: its pairs: larger chunks reuse more, more chunks keep every helper busy. Measured on the 4-D
#: double integrator (2 cores), vertex-LP rule: ``4^4`` grid 13.8 s in chunks of 64 against
#: 22.5 s in 29 chunks of 256 (one helper got them all); ``5^4`` 61.6 s in chunks of 64 against
#: 49-51 s in chunks of 256 (95,868 against 87,277 LPs).
_JOB_PAIRS = 64
_JOB_CHUNKS = 128
#: Refuting duals (and inputs of unrefuted LPs) kept per row structure (pair shape and horizon),
#: the most recently useful first.
_CERTIFICATES = 8


def _shape_key(job) -> bytes:
    """The part of a job that fixes its LPs' rows ``G`` up to the right-hand sides: the facet
    normals of ``S ⊖ W`` and ``P_j ⊖ W`` (pairs at the same offset share them exactly, one qhull
    run per pair shape)."""
    _, HS, _, Hj, _, _, _ = job
    return np.asarray(HS.shape, np.int64).tobytes() + HS.tobytes() + Hj.tobytes()


def _chunk_cost(chunk: list) -> int:
    """A chunk's work, roughly: rows x horizons x vertices of its pairs."""
    return sum((HS.shape[0] + Hj.shape[0]) * len(Ls) * len(Vi) for _, HS, _, Hj, _, Vi, Ls in chunk)


def _run(jobs: list, const: tuple, workers) -> list:
    """:func:`screen_pairs` over ``jobs`` in chunks of like shapes (sized by :data:`_JOB_PAIRS`):
    here, or on ``workers`` (helper processes, the costliest chunks handed out first). The
    chunks are the same either way, so the result does not depend on where they run."""
    order = sorted(range(len(jobs)), key=lambda a: _shape_key(jobs[a]))
    jobs = [jobs[a] for a in order]
    size = min(max(_JOB_PAIRS, -(-len(jobs) // _JOB_CHUNKS)), 4 * _JOB_PAIRS)
    chunks = [jobs[a:a + size] for a in range(0, len(jobs), size)]
    if workers is None or len(chunks) <= 1:
        return [r for c in chunks for r in screen_pairs(c, const)]
    first = sorted(range(len(chunks)), key=lambda c: -_chunk_cost(chunks[c]))
    futs = dict(zip(first, workers.submit_many([(0, screen_pairs, (chunks[c], const)) for c in first])))
    return [r for c in range(len(chunks)) for r in futs[c].result()]


def screen_pairs(jobs: list, const: tuple) -> list:
    """(VL) on the horizons of some pairs; a pure function of its arguments (module level, so
    that a helper process can run it).

    A dual point that refuted one vertex LP is tried first on the next LPs with the same rows
    (same pair shape and horizon; only the right-hand side moves with the pair and the vertex):
    :func:`dual_bounds` of the instance's own data below ``-tol`` drops the horizon with no
    HiGHS solve, on the same weak-duality evidence as a solved one. Likewise the inputs HiGHS
    found for an unrefuted LP are tried on the next vertices with the same rows: one that keeps
    a vertex's margin above ``-tol / 2`` shows that its LP cannot refute, and it is not solved.

    Parameters
    ----------
    jobs : list of ``(k, H_S, g_S, H_j, g_j, V_i, Ls)``
        A pair's index, the unit H-reps of ``S ⊖ W`` and ``P_j ⊖ W``, the source vertices
        ``(n_v, n)`` and its kept horizons in increasing order.
    const : tuple
        ``(A^t B (L_max, n, m), A^l (L_max + 1, n, n), box(U) lo, hi, tol per L, survivors,
        max_vertices, refuting duals kept per row structure)`` (read in the calling process, so
        that a helper process uses the caller's :data:`_CERTIFICATES`).

    Returns
    -------
    list of ``(k, dropped horizons, LPs solved, horizons dropped by a reused dual, LPs skipped)``
        An LP is skipped when an input sequence of an earlier unrefuted LP with the same rows
        shows that it cannot refute (:func:`_witnessed`): the result is the same as solving it.
    """

    AtB, Apow, ulo, uhi, tols, survivors, max_vertices, certificates = const
    h = new_highs()
    out = []
    duals: dict[tuple, list] = {}                 # (pair shape, L) -> refuting duals (R,), best first
    feasible: dict[tuple, list] = {}              # (pair shape, L) -> inputs of unrefuted LPs (L m,), latest first
    for job in jobs:
        k, HS, gS, Hj, gj, Vi, Ls = job
        shape = _shape_key(job)
        pair = _PairRows(HS, gS, Hj, gj, AtB, Apow)
        dropped, lps, reused, passed, witnessed = [], 0, 0, 0, 0
        for L in Ls:
            if passed >= survivors:
                break
            G, g, M = pair.rows(L)
            lo, hi = np.tile(ulo, L), np.tile(uhi, L)
            rhs_all = g[:, None] - M @ Vi.T                                   # (R, nv)
            # score: how far the vertex's unconstrained reach misses the rows (largest first)
            reach = rhs_all + np.abs(G) @ np.maximum(np.abs(lo), np.abs(hi))[:, None]
            order = np.argsort(np.min(reach, axis=0), kind="stable")[:max_vertices]
            tol = float(tols[L])
            known = duals.setdefault((shape, L), [])
            if known:
                b = dual_bounds(G, rhs_all[:, order], lo, hi, np.array(known))   # (K, V)
                hit = np.flatnonzero((b < -tol).any(axis=1))
                if hit.size:
                    known.insert(0, known.pop(int(hit[0])))
                    dropped.append(L)
                    reused += 1
                    continue
            points = feasible.setdefault((shape, L), [])
            shown = _witnessed(G, rhs_all[:, order], points, tol)          # (V,): cannot refute
            idx = np.arange(G.shape[0], dtype=np.int32)
            neg_inf = np.full(G.shape[0], -highspy.kHighsInf)
            fresh = True
            for a, v in enumerate(order.tolist()):
                if shown[a]:
                    witnessed += 1
                    continue
                if fresh:
                    h.clearSolver()
                    h.passModel(_model(G, rhs_all[:, v], lo, hi))
                    fresh = False
                else:
                    h.changeRowsBounds(len(idx), idx, neg_inf, rhs_all[:, v])
                h.run()
                lps += 1
                if h.getModelStatus() != highspy.HighsModelStatus.kOptimal:
                    continue
                sol = h.getSolution()
                y = np.maximum(-np.asarray(sol.row_dual), 0.0)
                if dual_bound(G, rhs_all[:, v], lo, hi, y) < -tol:
                    dropped.append(L)
                    known.insert(0, y / y.sum())
                    del known[certificates:]
                    break
                points.insert(0, np.clip(np.asarray(sol.col_value)[:-1], lo, hi))
                del points[certificates:]
            else:
                passed += 1
        out.append((k, dropped, lps, reused, witnessed))
    return out


def _witnessed(G: np.ndarray, rhs: np.ndarray, points: list, tol: float) -> np.ndarray:
    """Which right-hand sides ``rhs (R, V)`` a known input sequence (``points``, each in
    ``box(U)^L``, shape ``(L m,)``) shows cannot be refuted, shape ``(V,)`` of bool: its margin
    ``min_r (rhs_r - G_r u)`` is at least ``-tol / 2``, so ``t* >= -tol / 2`` and no dual bound
    falls below ``-tol`` (the LP is skipped: it could only keep the instance)."""
    if not points:
        return np.zeros(rhs.shape[1], dtype=bool)
    t = np.min(rhs[None, :, :] - (np.array(points) @ G.T)[:, :, None], axis=1)      # (P, V)
    return (t >= -0.5 * tol).any(axis=0)
