"""The product path's joint LPs with HiGHS, each first tried against earlier LPs' refuting duals.

Two tube problems with the same :func:`~tubejax.lp.declarations.tube_lp.rows_key` (pairs whose
cells differ by a translation) have the same unit-normalised margin rows ``G``; only ``g`` and the
bounds ``lb, ub`` differ. So any ``y >= 0`` with ``sum(y) > 0`` bounds the optimal margin of each
of them by weak duality on its own ``g``, ``lb``, ``ub``
(:func:`~tubejax.lp.evidence.decide.float_dual_bound`'s formula, docs/math/evidence.md#non-edges).
:class:`DualReuseSolver` keeps, per rows key, the duals of the last LPs HiGHS refuted
(:data:`KEPT_DUALS`); a new problem whose bound under one of them is below ``-MARGIN_SAFETY`` is
refuted as HiGHS's own dual would refute it (the ``'infeasible'`` branch of
:func:`~tubejax.lp.evidence.verdict.verdict_of_result`) without building its dense LP. Every
other problem is solved and confirmed as :func:`~tubejax.lp.evidence.verdict.highs_verdict` does,
so every edge comes from its own LP and proof, or from a representative's exact tube translated and checked
exactly against the problem's own data (``likely_edges`` with their ``representatives``, as
:func:`~tubejax.abstraction.translation_classes.solve_by_class` passes them); a refutation only drops a
pair at one ``L``.
An LP's dense rows are written only when its verdict reads them
(:class:`~tubejax.lp.declarations.tube_lp.DenseOnDemand`; HiGHS and an edge's exact proof read the
sparse rows and the problem's data): the verdict is then made again from the same answer, the same
verdict as with the dense rows from the start.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from ..lp.declarations.row_families import dense_rhs
from ..lp.declarations.sparse_blocks import csr_dense
from ..lp.declarations.tube_families import TUBE_FAMILIES, float_terms
from ..lp.declarations.tube_lp import DenseNeeded, DenseOnDemand, margin_csr, rows_key, with_dense_rows
from ..lp.declarations.tube_variables import tube_variable_bounds
from ..lp.engines.certify import MARGIN_SAFETY
from ..lp.engines.highs import solve_margin_lp
from ..lp.evidence.check_batch import exact_tube_violations
from ..lp.evidence.decide import Refutation
from ..lp.evidence.registry import formulation
from ..lp.evidence.translate_verdicts import (TUBE_CHECKS, TranslateChecks, system_translation_groups,
                                               translated_proofs)
from ..lp.evidence.verdict import CLEAR_MARGIN, Verdict, verdict_of_result

__all__ = ["DualReuseSolver", "KEPT_DUALS", "dual_bound"]

#: Refuting duals kept per rows key (the most recent ones, tried newest first).
KEPT_DUALS = 4
#: The note of an edge proved by its class representative's exact tube, translated.
_TRANSLATED = "the class representative's exact tube, translated"


def dual_bound(a, y: np.ndarray, gy: np.ndarray, lb: np.ndarray, ub: np.ndarray) -> float:
    """The weak-duality bound on ``t*`` of margin-row multipliers ``y (k,) >= 0`` with ``a = G^T y``,
    for those rows' unit right-hand sides ``gy (k,)`` and the variable bounds ``lb, ub (n_x,)``;
    ``inf`` when it cannot be formed.

    ``a`` is sparse: ``(indices, values)`` (its zeros add nothing to the bound).
    """
    ia, va = a
    s = float(np.sum(y))
    with np.errstate(all="ignore"):
        num = float(gy @ y + np.sum(np.maximum(-va * lb[ia], -va * ub[ia])))
    if not (s > 1e-300 and np.isfinite(num)):
        return float("inf")
    return num / s


def _dense_rows_of(lp, rows: np.ndarray) -> np.ndarray:
    """``lp.G[rows]``, shape ``(len(rows), n_x)``: where the dense rows are not written, only those rows,
    from ``lp.G_csr`` as :func:`~tubejax.lp.declarations.sparse_blocks.csr_dense` writes them (the same
    array, bit for bit)."""
    return csr_dense(lp.G_csr[rows]) if isinstance(lp.G, DenseOnDemand) else lp.G[rows]


def _sparse(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    k = np.flatnonzero(v)
    return k, v[k]


class DualReuseSolver:
    """A batch solver of tube problems: :func:`~tubejax.lp.evidence.verdict.highs_verdict`'s
    verdicts, one problem at a time, each problem first tried against the refuting duals of earlier
    ones with its rows (module docstring).

    Only the duals of the current horizon are kept (a problem of another ``L`` drops them: the
    product path poses its joint LPs horizon by horizon), each as its nonzeros.

    Parameters
    ----------
    solve_lp : callable, optional
        ``solve_lp(prob, lp) -> HighsResult``: HiGHS's answer for the full LP ``lp`` of ``prob`` (default: HiGHS
        on ``lp``, as :func:`~tubejax.lp.evidence.verdict.confirm_with_highs`; the product path passes
        :func:`~tubejax.abstraction.group_vertex_lp.solve_by_group_vertices`).

    Attributes
    ----------
    n_solved : int     problems HiGHS solved
    n_reused : int     problems refuted by an earlier problem's dual (no LP built)
    n_translated : int edges proved by a representative's exact tube, translated (no LP built)
    """

    method = "tube"
    #: :meth:`__call__` takes ``likely_edges`` and their ``representatives`` (see there).
    supports_likely_edges = True
    proves_from_representatives = True

    def __init__(self, solve_lp=None):
        self._solve_lp = solve_lp
        self._duals: dict = {}
        self._L = None
        self.n_solved = 0
        self.n_reused = 0
        self.n_translated = 0
        self._form = formulation("tube")

    def __call__(self, problems, progress=None, likely_edges=(), representatives=()) -> list:
        """The verdicts of ``problems`` (a list, length K), in order.

        Parameters
        ----------
        problems : sequence of TubeProblem
        progress : tqdm-like, optional
        likely_edges : sequence of sequences of int, optional
            Groups of indices into ``problems``: the exact translates of one representative edge.
        representatives : sequence of (TubeProblem, Verdict), optional
            Each group's representative and its verdict: a member whose translate of the representative's
            exact tube passes the exact check on its own data, and the float re-check, is an edge
            (:func:`~tubejax.lp.evidence.translate_verdicts.translated_proofs`); every other problem is
            solved on its own (:meth:`verdict`).
        """
        out: list = [None] * len(problems)
        for group, (rep, rep_verdict) in zip(likely_edges, representatives):
            group = list(group) if np.ndim(group) else [int(group)]
            proved = translated_proofs(rep, rep_verdict, [problems[a] for a in group], self._checks(rep, len(group)),
                                       _TRANSLATED)
            for k, v in proved.items():
                out[group[k]] = v
            self.n_translated += len(proved)
        for a, p in enumerate(problems):
            if out[a] is None:
                out[a] = self.verdict(p)
            if progress is not None:
                progress.update(1)
        return out

    def _checks(self, rep, k: int) -> TranslateChecks:
        """The exact checks of ``k`` translates of ``rep``: each member's own rows
        (:func:`~tubejax.lp.evidence.check_batch.exact_tube_violations`, one row evaluation per member, its
        exact data derived from ``rep``'s, already made for ``rep``'s proof, where it is ``rep``'s moved),
        or, for more than ``1 + G`` members (``G`` groups of axes), one check of ``rep``'s rows
        under each group's unit move (:func:`~tubejax.lp.evidence.check_batch.translated_tube_violations`,
        ``1 + G`` evaluations) and the members' data compared exactly with ``rep``'s moved."""
        groups = system_translation_groups(rep.system)
        if k > 1 + len(np.unique(groups[groups >= 0])):
            return TUBE_CHECKS
        return TUBE_CHECKS._replace(exact_batch=partial(exact_tube_violations, reference=rep), exact_translated=None)

    def verdict(self, prob) -> Verdict:
        """The verdict of one tube problem (``'infeasible'`` with a ``'dual'`` refutation whose
        ``bound`` is also the verdict's ``margin`` when an earlier dual refutes it)."""
        if prob.L != self._L:
            self._duals, self._L = {}, prob.L
        reusable = float(prob.min_margin) == 0.0 and prob.system.u_is_box
        key = rows_key(prob) if reusable else None
        kept = self._duals.get(key, [])
        if kept:
            g = dense_rhs(float_terms(prob), "margin", True, TUBE_FAMILIES)
            lb, ub = tube_variable_bounds(prob)
            for a, (iy, vy), nrm in reversed(kept):
                b = dual_bound(a, vy, g[iy] / nrm, lb, ub)
                if b < -MARGIN_SAFETY:
                    self.n_reused += 1
                    return Verdict("infeasible", b, None, self._form.provenance, None,
                                   Refutation("dual", b, note="the dual of an earlier LP with the same rows"))
        lp = self._form.build(prob, dense=False)          # the dense rows only where something reads them
        try:
            res = self._solved(prob, lp)
        except DenseNeeded:
            lp = with_dense_rows(lp)
            res = self._solved(prob, lp)
        try:
            v = self._verdict_of(prob, lp, res)
        except DenseNeeded:                 # the same verdict, from the same answer, with the dense rows
            lp = with_dense_rows(lp)
            v = self._verdict_of(prob, lp, res)
        self.n_solved += 1
        if (reusable and v.status == "infeasible" and getattr(v.refutation, "kind", None) == "dual"
                and res.y is not None and lp.G_hard.shape[0] == 0 and getattr(lp, "t_coef", None) is None):
            iy, vy = _sparse(np.maximum(np.nan_to_num(np.asarray(res.y, float), nan=0.0), 0.0))
            a = _sparse(_dense_rows_of(lp, iy).T @ vy)
            self._duals[key] = (kept + [(a, (iy, vy), margin_csr(prob, rhs=False)[2][iy])])[-KEPT_DUALS:]
        return v

    def _solved(self, prob, lp):
        """HiGHS's answer for ``prob``'s LP ``lp`` (as :func:`~tubejax.lp.evidence.verdict.confirm_with_highs`
        solves it, or by the ``solve_lp`` given)."""
        return (solve_margin_lp(lp, basis_min_margin=-CLEAR_MARGIN) if self._solve_lp is None
                else self._solve_lp(prob, lp))

    def _verdict_of(self, prob, lp, res) -> Verdict:
        """The verdict of HiGHS's answer ``res`` for ``prob``'s LP ``lp``
        (:func:`~tubejax.lp.evidence.verdict.verdict_of_result`; a subclass may settle some answers first)."""
        return verdict_of_result(prob, lp, res, self._form.violation, self._form.provenance)
