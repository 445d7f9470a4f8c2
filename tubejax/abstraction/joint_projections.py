"""Projections that refute joint LPs: Problem 2 on a few axis groups, a relaxation of the joint one.

The product path solves a joint LP (the paper's tube family, safe set ``co(P_i u P_j)``) for each pair
whose bounding box meets an obstacle while its hull does not (docs/math/product.md). Project such a
problem on a set ``S`` of axis groups: the cells, ``Z`` and the safe set onto those groups' axes, the
system onto its ``S`` blocks. Every feasible joint tube projects onto a feasible tube of the projected
problem, with at least the same margin (docs/math/product.md#projections-that-refute-joint-lps): its
dynamics rows are rows of the joint problem, and the projection of a ball inside ``co(P_i u P_j)`` is a
ball inside ``co(P_i|S u P_j|S)``. So a projected problem proved infeasible refutes the joint one at
that horizon, and the joint LP is never built. A projection never proves an edge: the pairs it does not
refute go to the joint LP as before, so the transition system is the same.

Many pairs share a projection (the factor cells of ``S`` only), and pairs whose projections are exact
translates, or exact mirror images of translates (a group's axes and inputs negated, where the system is
exactly symmetric: :func:`~tubejax.abstraction.translation_classes.system_reflections`), share one solve
(:func:`~tubejax.abstraction.translation_classes.solve_by_class`). What does
not depend on ``L`` is kept: each joint cell's projected cell, and the last horizon's projected problems
(their pair hulls). The tube of a clearly feasible projection is not proved (:class:`_ScreenSolver`): it
refutes nothing either way.
"""

from __future__ import annotations

import dataclasses
import itertools
import logging
import time
from types import SimpleNamespace

import numpy as np

from ..model.geometry import Polytope
from ..model.problem import TubeProblem
from ..model.product_structure import ProductStructure, factor_system
from ..model.system import LinearSystem
from ..model.workspace.pair_hulls import pair_hull_polytopes
from ..lp.engines.certify import MARGIN_SAFETY
from ..lp.evidence.decide import EXACT_BAND, Refutation, float_dual_bound_at_most
from ..lp.evidence.verdict import Verdict, unproved_verdict_of_result
from .group_vertex_lp import group_vertex_answer, solve_by_group_vertices
from .joint_duals import DualReuseSolver
from .translation_classes import TranslationClasses, solve_by_class, system_reflections

__all__ = ["ProjectionScreen", "projection_sets", "product_polytope"]

log = logging.getLogger("tubejax")


def projection_sets(n_groups: int) -> list:
    """The sets of groups the joint problems are projected on: every set of ``min(2, n_groups - 1)``
    groups, in lexicographic order (two groups are the smallest projection that keeps a pair hull that is
    not a box; the full set is the joint problem itself)."""
    return [tuple(s) for s in itertools.combinations(range(n_groups), min(2, n_groups - 1))]


def product_polytope(parts) -> Polytope:
    """The product of ``parts`` (Polytope, in order): vertices in the product order of the parts' vertices
    (the last part's varying fastest), shape ``(prod n_v, sum dim)``, and the block-diagonal H-rep.
    Boxes give :meth:`Polytope.box` (its canonical order pairs the corners of two boxes by the same bits)."""
    if all(p.is_box for p in parts):
        return Polytope.box(np.concatenate([p.bounding_box()[0] for p in parts]),
                            np.concatenate([p.bounding_box()[1] for p in parts]))
    V = np.array([np.concatenate(vs) for vs in itertools.product(*(p.vertices for p in parts))])
    dims = [p.dim for p in parts]
    H = np.zeros((sum(p.H.shape[0] for p in parts), sum(dims)))
    r = c = 0
    for p, d in zip(parts, dims):
        H[r:r + p.H.shape[0], c:c + d] = p.H
        r, c = r + p.H.shape[0], c + d
    return Polytope(V, H, np.concatenate([p.h for p in parts]))


class _Projection:
    """One set of groups: its system and its cells (and ``Z``), made as pairs need them."""

    def __init__(self, structure: ProductStructure, system: LinearSystem, groups: tuple):
        self.groups = groups
        self._of_cell = np.full(len(structure.cell_factor), -1, dtype=np.int64)   # joint cell -> projected id
        f = [structure.factors[g] for g in groups]
        axes = [a for x in f for a in x.axes]
        inputs = [a for x in f for a in x.inputs]
        self.system = factor_system(system, axes, inputs, np.unique(system.U.vertices[:, inputs], axis=0))
        self.reflections = system_reflections(self.system, [k for k, x in enumerate(f) for _ in x.axes],
                                              [k for k, x in enumerate(f) for _ in x.inputs])
        self.factors = f
        self.cells: list = []
        self.Z: list = []
        self._id: dict = {}

    def cell_ids(self, combos: np.ndarray) -> np.ndarray:
        """The id of the projected cell of each row of factor cells ``combos (K, |S|)``, shape ``(K,)``."""
        rows, inv = np.unique(combos, axis=0, return_inverse=True)
        ids = np.empty(len(rows), dtype=np.int64)
        for k, key in enumerate(map(tuple, rows.tolist())):
            i = self._id.get(key)
            if i is None:
                i = self._id[key] = len(self.cells)
                self.cells.append(product_polytope([x.cells[c] for x, c in zip(self.factors, key)]))
                self.Z.append(product_polytope([x.Z[c] for x, c in zip(self.factors, key)]))
            ids[k] = i
        return ids[np.ravel(inv)]

    def ids_of(self, cell_factor: np.ndarray, cells: np.ndarray) -> np.ndarray:
        """The projected cell id of each joint cell ``cells (K,)``, shape ``(K,)``, from ``cell_factor (N, n_groups)``;
        kept per joint cell (a projected cell never changes), so only cells not met before go through
        :meth:`cell_ids` (which numbers new projected cells in the order it always did)."""
        new = np.unique(cells[self._of_cell[cells] < 0])
        if new.size:
            self._of_cell[new] = self.cell_ids(cell_factor[new][:, list(self.groups)])
        return self._of_cell[cells]


class _ScreenSolver(DualReuseSolver):
    """:class:`~tubejax.abstraction.joint_duals.DualReuseSolver` for projected problems, which only refute:
    the tube of a clearly feasible projected problem is not proved
    (:func:`~tubejax.lp.evidence.verdict.unproved_verdict_of_result`: ``'unconfirmed'`` where
    :func:`~tubejax.lp.evidence.verdict.verdict_of_result` would prove a clear edge). Either way the projection
    refutes nothing, so the refuted pair horizons are the same, without the exact proofs of tubes no one uses.

    An optimum below ``-EXACT_BAND`` whose float dual bound is below ``-MARGIN_SAFETY`` is refuted as
    :func:`~tubejax.lp.evidence.verdict.verdict_of_result` refutes it, the bound decided without the dense
    rows where they cannot decide otherwise (:func:`~tubejax.lp.evidence.decide.float_dual_bound_at_most`, or
    :func:`~tubejax.abstraction.group_vertex_lp.group_vertex_answer`, which has just checked it); its
    refutation records ``-MARGIN_SAFETY``, a weaker upper bound of ``t*`` than the dense bound (only the
    status is read: a projection keeps "refuted or not").
    """

    #: A projection's edge is never proved, so its translates are not proved from their representative either.
    supports_likely_edges = False
    proves_from_representatives = False

    def __init__(self, solve_lp=None):
        super().__init__(solve_lp)
        self._refuting = None                   # the last answer group_vertex_answer knew to refute its LP

    def _solved(self, prob, lp):
        if self._solve_lp is not solve_by_group_vertices:
            return super()._solved(prob, lp)
        res, refutes = group_vertex_answer(prob, lp)
        self._refuting = res if refutes else None
        return res

    def _verdict_of(self, prob, lp, res) -> Verdict:
        if (res.status == "Optimal" and float(prob.min_margin) == 0.0 and res.margin < -EXACT_BAND
                and (res is self._refuting or float_dual_bound_at_most(lp, res, -MARGIN_SAFETY, strict=True))):
            return Verdict("infeasible", res.margin, None, self._form.provenance, None,
                           Refutation("dual", -MARGIN_SAFETY, note="the float dual bound is below -MARGIN_SAFETY"))
        return unproved_verdict_of_result(prob, lp, res, self._form.violation, self._form.provenance)


class ProjectionScreen:
    """Refutes joint LPs by their projections on sets of axis groups (module docstring).

    Parameters
    ----------
    structure : ProductStructure
    system : LinearSystem
        The full system (``structure``'s factors' blocks are its blocks).
    eps_min : float
    solve_batch : callable, optional
        A batch solver of tube problems for the projected LPs (default
        :class:`_ScreenSolver`: HiGHS with reused refuting duals, the tubes of clearly feasible projections
        not proved).

    Attributes
    ----------
    n_lps : int          projected problems solved
    n_translated : int   projected problems settled by a translate's refutation, not solved
    n_refuted : int      pair horizons refuted
    """

    def __init__(self, structure: ProductStructure, system: LinearSystem, eps_min: float = 0.0, solve_batch=None):
        self.structure = structure
        self.eps_min = float(eps_min)
        self.solve_batch = solve_batch if solve_batch is not None else _ScreenSolver(solve_by_group_vertices)
        self.projections = ([_Projection(structure, system, s) for s in projection_sets(structure.n_groups)]
                            if structure.n_groups >= 2 else [])
        self._refuted: dict = {}                          # (projection, L) -> {(a, b): refuted}
        self._hull_shapes: dict = {}
        self._last: dict = {}                             # projection -> {(a, b): its problem at the last L}
        self.n_lps = 0
        self.n_translated = 0
        self.n_refuted = 0

    def refuted(self, src: np.ndarray, dst: np.ndarray, L: int) -> np.ndarray:
        """Whether a projection of the joint problem of ``(src[k], dst[k])`` at ``L`` is proved infeasible,
        shape ``(K,)`` bool (``False``: not refuted, the joint LP decides)."""
        src, dst = np.asarray(src, dtype=np.int64), np.asarray(dst, dtype=np.int64)
        out = np.zeros(len(src), dtype=bool)
        cf = self.structure.cell_factor
        for n, proj in enumerate(self.projections):
            open_ = np.flatnonzero(~out)
            a, b = proj.ids_of(cf, src[open_]), proj.ids_of(cf, dst[open_])
            moves = np.flatnonzero(a != b)              # a projection that stays put is a factor LP: skipped
            if moves.size == 0:
                continue
            keys, inv = np.unique(np.column_stack([a[moves], b[moves]]), axis=0, return_inverse=True)
            hit = self._decide(n, proj, keys, int(L))[np.ravel(inv)]
            out[open_[moves[hit]]] = True
        self.n_refuted += int(out.sum())
        return out

    def _decide(self, n: int, proj: _Projection, keys: np.ndarray, L: int) -> np.ndarray:
        """Whether each projected problem ``keys (K, 2)`` (projected cell ids) at ``L`` is proved infeasible,
        shape ``(K,)``; those not decided before are solved now."""
        known = self._refuted.setdefault((n, L), {})
        new = [(x, y) for x, y in keys.tolist() if (x, y) not in known]
        if new:
            t0 = time.perf_counter()
            a, b = np.array(new, dtype=np.int64).T
            ids = np.unique(np.concatenate([a, b]))
            cells = [proj.cells[i] for i in ids.tolist()]
            la, lb = np.searchsorted(ids, a), np.searchsorted(ids, b)
            probs = self._problems(n, proj, new, cells, la, lb, L)
            classes = TranslationClasses(SimpleNamespace(cells=cells), proj.system, proj.reflections)
            verdicts, n_translated = solve_by_class(self.solve_batch, classes, probs, la, lb,
                                                    np.zeros(len(probs), dtype=bool))
            self.n_lps += len(probs) - n_translated
            self.n_translated += n_translated
            for key, v in zip(new, verdicts):
                known[key] = (v if hasattr(v, "status") else v.result()).status == "infeasible"
            log.info("projections on groups %s at L = %d: %d problems (%d settled by a translate), %d refuted, "
                     "%.1f s", proj.groups, L, len(new), n_translated, sum(known[k] for k in new),
                     time.perf_counter() - t0)
        return np.array([known[(x, y)] for x, y in keys.tolist()], dtype=bool)

    def _problems(self, n: int, proj: _Projection, new: list, cells: list, la, lb, L: int) -> list:
        """The projected problems of the keys ``new`` (length K) at ``L``: those met at the last horizon this
        projection was asked are that problem with ``L`` replaced (its safe set, the pair hull, and its box do
        not depend on ``L``), the others are built (``cells``: the cells of ``new``, ``la, lb (K,)`` their
        places in it). Only the last horizon's problems are kept."""
        last = self._last.get(n, {})
        probs = [dataclasses.replace(last[k], L=L) if k in last else None for k in new]
        todo = [k for k, p in enumerate(probs) if p is None]
        hulls = pair_hull_polytopes(cells, la[todo], lb[todo], self._hull_shapes)
        for k, hull in zip(todo, hulls):
            x, y = new[k]
            (lo1, hi1), (lo2, hi2) = proj.cells[x].bounding_box(), proj.cells[y].bounding_box()
            probs[k] = TubeProblem(proj.system, proj.cells[x], proj.cells[y], hull, proj.Z[x], L,
                                   (np.minimum(lo1, lo2), np.maximum(hi1, hi2)), self.eps_min)
        self._last[n] = dict(zip(new, probs))
        return probs
