"""Pruning by one small LP per vertex: can the vertex reach ``P_j ⊖ W`` while staying in ``S ⊖ W``?

(VL) is ``max t  s.t.  G_v u + t 1 <= g_v,  u ∈ box(U)^L,  t <= 1`` in the inputs only, with unit
state-space rows ``G_v``. HiGHS only proposes a dual point; a horizon is dropped only when its
weak-duality bound, in float64, is below ``-tol_L``. Why this is sound, non-box ``U`` included:
docs/math/evidence.md#the-vertex-lp. The rows depend only on the pair's shape and ``L``, so pairs
are screened sorted by shape (:mod:`tubejax.abstraction.vertex_screen`,
docs/explanation/solvers.md#pruning).
"""

from __future__ import annotations

import numpy as np

from ..model.geometry import support
from .pruning import ReachTables, _padded_vertices
from ..model.system import LinearSystem
from .translation_classes import TranslationClasses
from ..model.workspace.decomposition import CellDecomposition
from .vertex_screen import screen_pairs, shape_key

__all__ = ["vertex_lp_keep", "VERTEX_LP_MIN_DIM"]

#: The rule runs by default in state dimensions of at least this (in 2-D the cheap tests are
#: already exact for most instances and the LPs cost more than they save).
VERTEX_LP_MIN_DIM = 3
#: Horizons below this are left alone (at ``L = 1`` there is no ``S`` constraint and the vertex test
#: of :mod:`tubejax.abstraction.pruning` already decides the same condition).
MIN_L = 2
#: Per pair, horizons are screened in increasing order until this many passed (every vertex LP
#: feasible); the later ones are kept unscreened. Algorithm 2 solves a horizon only when every smaller
#: one failed, and a pair whose vertices all reach at ``L`` is often an edge there: screening its later
#: horizons would mostly be wasted.
SURVIVORS = 2
#: Vertex LPs solved at most per instance, the highest scores first (``None``: all). Fewer only keeps
#: more instances, and the highest scores find most drops (docs/explanation/performance.md#the-vertex-lp-rule).
MAX_VERTICES = 4


class _ShrunkRows:
    """``P ⊖ W = {x : H x <= h - σ_W(H)}`` (exact for the support function), unit rows: called as
    ``(H (f, n), h (f,))``, returns ``(unit rows (f, n), offsets (f,))``. What depends only on the
    normals is done once per normals array (shared by pair hulls of one shape); ``keys`` maps the id of
    each unit-row array to its bytes."""

    def __init__(self, W):
        self.W = W
        self._by_id: dict = {}                   # id(H) -> (H, unit rows, norms, sigma_W)
        self.keys: dict = {}

    def __call__(self, H, h) -> tuple[np.ndarray, np.ndarray]:
        hit = self._by_id.get(id(H))
        if hit is None or hit[0] is not H:
            nrm = np.linalg.norm(H, axis=1)
            Hu = H / nrm[:, None]
            hit = self._by_id[id(H)] = (H, Hu, nrm, support(self.W, Hu))
            self.keys[id(Hu)] = Hu.tobytes()
        _, Hu, nrm, sig = hit
        return Hu, h / nrm - sig


def vertex_lp_keep(decomp: CellDecomposition, system: LinearSystem, T: ReachTables, src, dst, obstacle,
                   keep: np.ndarray, workers=None) -> tuple[np.ndarray, int, int, int, int]:
    """Apply (VL) to the kept instances; returns ``(keep, n_pruned, n_lps, n_reused, n_witnessed)``.

    Parameters
    ----------
    src, dst : ndarray of int, shape (K,)
    obstacle : ndarray of bool, shape (K,)
    keep : ndarray of bool, shape (K, L_max)
        The instances still kept (the result is a copy with the dropped ones False).
    workers : optional
        A pool with ``submit_many`` (:class:`~tubejax.lp.engines.workers.ProcessWorkers`): the
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
        the class (:mod:`tubejax.abstraction.translation_classes`).
    n_reused : int
        Horizons dropped by a dual point reused from an earlier LP of the same rows, with no LP of
        their own (:func:`screen_pairs`).
    n_witnessed : int
        Vertex LPs not solved because the inputs of an earlier unrefuted LP of the same rows show
        that they cannot refute (:func:`screen_pairs`).
    """
    keep = np.array(keep, dtype=bool, copy=True)
    if len(src) == 0:
        return keep, 0, 0, 0, 0
    L_max = keep.shape[1]
    W = system.W
    ulo, uhi = system.U.bounding_box()
    const = (np.asarray(system.A, float), np.asarray(system.B, float), np.asarray(ulo, float),
             np.asarray(uhi, float), np.asarray(T.tol, float)[:L_max + 1], SURVIVORS, MAX_VERTICES,
             int(_CERTIFICATES))
    V = _padded_vertices(decomp)
    todo = np.flatnonzero(keep[:, MIN_L - 1:].any(axis=1))
    if todo.size == 0:
        return keep, 0, 0, 0, 0
    # one screen per exact translation class (tubejax.abstraction.translation_classes: the same result), the same kept horizons
    rep = TranslationClasses(decomp, system).group(np.asarray(src)[todo], np.asarray(dst)[todo],
                                                   np.asarray(obstacle, bool)[todo], keep[todo, MIN_L - 1:])
    members = todo
    todo = todo[rep == np.arange(len(todo))]
    rep_of = dict(zip(members.tolist(), members[rep].tolist()))
    free = todo[~np.asarray(obstacle, bool)[todo]]
    hull_of = dict(zip(free.tolist(), decomp.pair_hull_hreps(np.asarray(src)[free], np.asarray(dst)[free])))
    rows, cols = np.nonzero(keep[todo, MIN_L - 1:])
    horizons = np.split((cols + MIN_L).tolist(), np.cumsum(np.bincount(rows, minlength=len(todo)))[:-1])
    shrunk = _ShrunkRows(W)
    cells: dict = {}                               # cell -> its shrunk unit rows, offsets and vertices

    def of_cell(c: int) -> tuple:
        hit = cells.get(c)
        if hit is None:
            P = decomp.cells[c]
            hit = cells[c] = (*shrunk(P.H, P.h), V[c, :P.n_vertices])
        return hit

    jobs = []
    for k, Ls in zip(todo.tolist(), horizons):
        i, j = int(src[k]), int(dst[k])
        HS, gS, Vi = of_cell(i)
        Hj, gj, _ = of_cell(j)
        hull = hull_of.get(k)
        if hull is not None:
            HS, gS = shrunk(*hull)
        jobs.append((k, HS, gS, Hj, gj, Vi, Ls.tolist()))
    results = _run(jobs, const, workers, shrunk.keys)
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
#: its pairs: larger chunks reuse more, more chunks keep every helper busy
#: (docs/explanation/performance.md#the-vertex-lp-rule).
_JOB_PAIRS = 64
_JOB_CHUNKS = 128
#: Refuting duals (and inputs of unrefuted LPs) kept per row structure (pair shape and horizon),
#: the most recently useful first.
_CERTIFICATES = 8


def _shape_key(job, keys: dict | None = None) -> bytes:
    """The part of a job that fixes its LPs' rows ``G`` up to the right-hand sides
    (:func:`~tubejax.abstraction.vertex_screen.shape_key`: pairs at the same offset share them
    exactly, one qhull run per pair shape); ``keys``: known bytes of row arrays, by id."""
    _, HS, _, Hj, _, _, _ = job
    if keys is None:
        return shape_key(HS, Hj)
    return shape_key(HS, Hj, keys[id(HS)], keys[id(Hj)])


def _chunk_cost(chunk: list) -> int:
    """A chunk's work, roughly: rows x horizons x vertices of its pairs."""
    return sum((HS.shape[0] + Hj.shape[0]) * len(Ls) * len(Vi) for _, HS, _, Hj, _, Vi, Ls in chunk)


def _run(jobs: list, const: tuple, workers, keys: dict | None = None) -> list:
    """:func:`screen_pairs` over ``jobs`` in chunks of like shapes (sized by :data:`_JOB_PAIRS`):
    here, or on ``workers`` (helper processes, the costliest chunks handed out first). The
    chunks are the same either way, so the result does not depend on where they run.
    ``keys``: the bytes of the jobs' unit-row arrays by id (:class:`_ShrunkRows`), if known."""
    order = sorted(range(len(jobs)), key=lambda a: _shape_key(jobs[a], keys))
    jobs = [jobs[a] for a in order]
    size = min(max(_JOB_PAIRS, -(-len(jobs) // _JOB_CHUNKS)), 4 * _JOB_PAIRS)
    chunks = [jobs[a:a + size] for a in range(0, len(jobs), size)]
    if workers is None or len(chunks) <= 1:
        return [r for c in chunks for r in screen_pairs(c, const)]
    first = sorted(range(len(chunks)), key=lambda c: -_chunk_cost(chunks[c]))
    futs = dict(zip(first, workers.submit_many([(0, screen_pairs, (chunks[c], const)) for c in first])))
    return [r for c in range(len(chunks)) for r in futs[c].result()]
