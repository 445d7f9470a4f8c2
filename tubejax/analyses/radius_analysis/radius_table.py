"""``rho*(i, j, L)`` of every candidate instance from one batched solve (docs/math/radius.md).

With ``W = rho W_0`` Problem 2 is feasible iff ``rho <= rho*(i, j, L)``, so one LP per candidate
``(pair, L <= L_max)`` gives the transition system at every radius and every smaller ``L_max``.
:func:`solve_radius_table` solves them all (batched: :func:`~tubejax.lp.batch.batch_solver.pdhg_solver` with
``radius=True``; or by HiGHS) into a :class:`RadiusTable`: per instance an estimate of ``rho*`` and a bracket
``[lower, upper]`` (``upper`` a rigorous float64 dual bound). Candidates are pruned at ``rho = 0``, sound for
every ``rho >= 0`` (docs/math/radius.md#pruning-at-zero). :meth:`RadiusTable.refine` solves with HiGHS every
instance that may attain a pair's maximum, so ``rho*_ij`` is HiGHS's value, not a bracket (grid maps tie exactly
at round radii).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from ...abstraction.candidates import build_candidates
from ...lp.evidence.radius_lp import radius_highs_optimum
from ...lp.declarations.formulation import PdhgForm
from ...lp.evidence.registry import check_state_constraints, formulation, formulation_of_form, radius_forms
from ...model.zshape.kinds import cross_sections
from ...lp.declarations.radius_disturbance import unit_disturbance, zero_disturbance_system
from ...model.problem import Pairs, pair_problems
from ...model.system import LinearSystem
from ...abstraction.translation_classes import TranslationClasses
from ...model.workspace.decomposition import CellDecomposition
from ...lp.batch.batch_solver import pdhg_solver
from .step_functions import StepFunction, step_function

__all__ = ["RHO_TIE_TOL", "RadiusTable", "RadiusTableOptions", "PairCritical", "solve_radius_table", "highs_map"]


#: Radii within this distance of an instance's bracket are decided by HiGHS (radius units); a
#: rigorous upper bound this close below ``0`` (float64 rounding) does not rule a pair out.
RHO_TIE_TOL = 1e-7


class PairCritical(NamedTuple):
    """Each pair's critical disturbance ``rho*_ij = max_{L <= L_max} rho*(i, j, L)``, shape ``(P,)``.

    ``value`` is the best estimate (HiGHS's where :attr:`exact`), ``lower`` / ``upper`` bracket
    it (``upper`` rigorous); ``exact`` says the maximum is HiGHS's exactly (every instance
    that could exceed it was solved by HiGHS). ``best_L`` is the horizon attaining ``value``.
    """

    src: np.ndarray
    dst: np.ndarray
    value: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    exact: np.ndarray
    best_L: np.ndarray


def highs_map(fn, args: list, workers=None) -> list:
    """``[fn(*a) for a in args]``, half of them in ``workers`` (a
    :class:`~tubejax.lp.engines.workers.ProcessWorkers`) while this thread does the other half."""
    if workers is None or len(args) < 2:
        return [fn(*a) for a in args]
    remote = list(range(1, len(args), 2))
    futs = workers.submit_many([(0, fn, tuple(args[k])) for k in remote])
    out = [None] * len(args)
    for k in range(0, len(args), 2):
        out[k] = fn(*args[k])
    for k, f in zip(remote, futs):
        out[k] = f.result()
    return out


def _pair_max(values: np.ndarray, inv: np.ndarray, P: int) -> np.ndarray:
    """Per pair, the largest of ``values`` (K,) over its instances (``inv`` (K,): each one's pair), shape
    ``(P,)``: ``-inf`` for a pair without one; for booleans, whether any of them is set."""
    out = np.zeros(P, dtype=bool) if values.dtype == bool else np.full(P, -np.inf)
    np.maximum.at(out, inv, values)
    return out


def _rho_highs(problem, form: str) -> float:
    return float(radius_highs_optimum(problem, form)[0])


@dataclass(eq=False)
class RadiusTable:
    """``rho*(i, j, L)`` of every candidate instance of one form, sorted by ``(src, dst, L)``.

    Attributes
    ----------
    decomposition, system, Z, eps_min
        The problem (``system.W`` gives the shape ``W_0``; its size is ignored).
    W0 : Ball or Polytope
        ``W = rho W_0`` (:func:`~tubejax.lp.declarations.radius_disturbance.unit_disturbance`).
    form : {'tube', 'openloop'}
    L_max : int
    src, dst, L : ndarray of int, shape (K,)
    obstacle : ndarray of bool, shape (K,)
    value, lower, upper : ndarray, shape (K,)
        Estimate and bracket of ``rho*`` (``upper``: rigorous float64 dual bound; HiGHS's
        value for all three where ``provenance == 'highs'``; ``-inf`` for an LP HiGHS finds
        infeasible, impossible with the radius form's ``rho_min``).
    status, provenance : ndarray of str, shape (K,)
        As in :class:`~tubejax.lp.batch.optimise_mode.PdhgOptimum` (``'highs'``: solved by HiGHS).
    exact : ndarray, shape (K,)
        HiGHS's ``rho*`` where HiGHS solved the instance, else NaN.
    stats : dict
        Counts and seconds (``solve_seconds``, ``compile_seconds``, ``refine_seconds``, ...).
    rep : ndarray of int, shape (K,)
        The instance whose solve stands for this one (an exact translate with the same ``L``: the same
        ``rho*``), or itself; only representatives are solved.
    """

    decomposition: CellDecomposition
    system: LinearSystem
    Z: tuple
    W0: object
    form: str
    L_max: int
    eps_min: float
    src: np.ndarray
    dst: np.ndarray
    L: np.ndarray
    obstacle: np.ndarray
    value: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    status: np.ndarray
    provenance: np.ndarray
    exact: np.ndarray
    stats: dict = field(default_factory=dict)
    rep: np.ndarray | None = None

    def __post_init__(self):
        if self.rep is None:
            self.rep = np.arange(len(self.src))

    @property
    def n_instances(self) -> int:
        return len(self.src)

    def problems(self, ks, system: LinearSystem | None = None) -> list:
        """The tube problems of instances ``ks`` (in that order) for ``system`` (default :attr:`system`)."""
        ks = np.asarray(ks, dtype=int)
        system = self.system if system is None else system
        out = [None] * len(ks)
        for L in np.unique(self.L[ks]):
            at = np.flatnonzero(self.L[ks] == L)
            k = ks[at]
            pairs = Pairs(self.src[k], self.dst[k], self.obstacle[k])
            for a, p in zip(at, pair_problems(self.decomposition, system, self.Z, pairs, int(L), self.eps_min)):
                out[a] = p
        return out

    def _key(self, src, dst) -> np.ndarray:
        """One integer per ordered pair ``(src, dst)`` (arrays of cell ids)."""
        return np.asarray(src, np.int64) * self.decomposition.n_cells + np.asarray(dst)

    def _pair_ids(self, L_max: int | None):
        """``(mask, pair_of_instance, first_instance_of_pair)`` over the instances with ``L <= L_max``."""
        L_max = self.L_max if L_max is None else int(L_max)
        if not 1 <= L_max <= self.L_max:
            raise ValueError(f"L_max: expected an integer in [1, {self.L_max}] (the table's L_max), got {L_max}")
        mask = self.L <= L_max
        _, first, inv = np.unique(self._key(self.src[mask], self.dst[mask]), return_index=True, return_inverse=True)
        return np.flatnonzero(mask), inv, first

    def critical(self, L_max: int | None = None) -> PairCritical:
        """Each pair's critical disturbance over the horizons ``L <= L_max`` (default the table's)."""
        idx, inv, first = self._pair_ids(L_max)
        P = len(first)
        solved = ~np.isnan(self.exact[idx])
        ex = self.exact[idx]
        val = np.where(solved, ex, self.value[idx])
        value = _pair_max(val, inv, P)
        lower = _pair_max(np.where(solved, ex, self.lower[idx]), inv, P)
        upper = _pair_max(np.where(solved, ex, self.upper[idx]), inv, P)
        best_exact = _pair_max(np.where(solved, ex, -np.inf), inv, P)
        any_solved = _pair_max(solved, inv, P)
        open_ = _pair_max(~solved & (self.upper[idx] >= best_exact[inv]), inv, P)   # could still exceed it
        exact = any_solved & ~open_
        value, lower, upper = (np.where(exact, best_exact, a) for a in (value, lower, upper))
        order = np.lexsort((self.L[idx], -val, inv))     # per pair: largest value, then smallest L
        head = np.unique(inv[order], return_index=True)[1]
        best = self.L[idx[order[head]]]
        return PairCritical(self.src[idx[first]], self.dst[idx[first]], value, lower, upper, exact, best)

    def n_edges(self, L_max: int | None = None, which: str = "value") -> StepFunction:
        """``n_edges(rho)`` over ``rho >= 0`` from the pairs' critical values (``which``: ``'value'``,
        ``'lower'`` or ``'upper'``, the last a rigorous upper bound of the count)."""
        if which not in ("value", "lower", "upper"):
            raise ValueError(f"which: expected 'value', 'lower' or 'upper', got {which!r}")
        return step_function(getattr(self.critical(L_max), which))

    def refine(self, pairs=None, L_max: int | None = None, workers=None) -> int:
        """Make pairs' critical values exact: solve with HiGHS every instance that may attain a
        pair's maximum over ``L <= L_max`` (those whose ``upper`` reaches the best value known,
        largest estimate first, until none is left). ``pairs``: ``(src, dst)`` arrays, or None
        for every pair whose ``upper >= -RHO_TIE_TOL`` (all that can be an edge at some radius).

        Returns the number of HiGHS solves made.
        """
        t0 = time.perf_counter()
        idx, inv, first = self._pair_ids(L_max)
        P = len(first)
        if pairs is None:
            want = self.critical(L_max).upper >= -RHO_TIE_TOL
        else:
            want = np.isin(self._key(self.src[idx[first]], self.dst[idx[first]]), self._key(*pairs))
        n_solved = 0
        tried = ~np.isnan(self.exact[idx])
        while True:
            known = tried & ~np.isnan(self.exact[idx])
            best = _pair_max(np.where(known, self.exact[idx], -np.inf), inv, P)
            any_exact = _pair_max(known, inv, P)
            est = _pair_max(np.where(tried, -np.inf, self.value[idx]), inv, P)
            # first the best estimate of a pair without an exact value, then every rival
            todo = ~tried & want[inv] & np.where(any_exact[inv], self.upper[idx] >= best[inv],
                                                 self.value[idx] >= est[inv])
            ks = idx[todo]
            if not ks.size:
                break
            reps = np.unique(self.rep[ks])                    # a translate's value is its representative's
            reps = reps[np.isnan(self.exact[reps])]
            self.exact[reps] = highs_map(_rho_highs, [(p, self.form) for p in self.problems(reps)], workers)
            self.exact[ks] = self.exact[self.rep[ks]]
            tried[todo] = True
            n_solved += len(reps)
        self.stats["refine_highs_solves"] = self.stats.get("refine_highs_solves", 0) + n_solved
        self.stats["refine_seconds"] = self.stats.get("refine_seconds", 0.0) + time.perf_counter() - t0
        return n_solved


def _check_inputs(form: str, system: LinearSystem, L_max) -> None:
    """Refuse an unknown ``form``, state constraints the form has no rows for, or a bad ``L_max``."""
    if form not in radius_forms():
        raise ValueError(f"form: expected one of {radius_forms()}, got {form!r}")
    check_state_constraints(form, system)              # the open-loop form has no rows for them
    if not isinstance(L_max, (int, np.integer)) or L_max < 1:
        raise ValueError(f"L_max must be an integer >= 1, got {L_max!r}")


class RadiusTableOptions(NamedTuple):
    """What :func:`solve_radius_table` solves: the LP form and the candidates.

    Attributes
    ----------
    form : {'tube', 'openloop'}
    L_max : int
        Largest horizon, ``>= 1``.
    eps_min : float
        ``eps_l >= eps_min`` (C1).
    pruning : bool
        Prune the candidates by the sound necessary conditions at ``rho = 0``, and solve one instance per
        exact translation class (translates have the same ``rho*``).
    """

    form: str = "tube"
    L_max: int = 10
    eps_min: float = 0.0
    pruning: bool = True


def solve_radius_table(decomp: CellDecomposition, system: LinearSystem, *, Z: tuple,
                       options: RadiusTableOptions = RadiusTableOptions(), solver="pdhg", workers=None,
                       progress=None) -> RadiusTable:
    """``rho*(i, j, L)`` of every candidate ``(pair, L <= L_max)``, pruned at ``rho = 0``.

    Parameters
    ----------
    decomp : CellDecomposition
    system : LinearSystem
        Its ``W`` fixes the shape ``W_0`` (a ball, a cube or a polytope with ``0`` inside).
    Z : tuple of Polytope, length N
        The cross-section of each cell (:func:`tubejax.model.zshape.kinds.cross_sections`).
    options : RadiusTableOptions
    solver : 'pdhg', 'highs' or PdhgBatchSolver
        ``'pdhg'``: a new :func:`~tubejax.lp.batch.batch_solver.pdhg_solver` on ``form``'s radius form, or one
        (``pdhg_solver(form, radius=True)``) reusing its executables; HiGHS decides what it leaves unsettled.
        ``'highs'``: HiGHS for every instance (the reference).
    workers : ProcessWorkers, optional
        Where half of the HiGHS solves run (:func:`highs_map`).
    progress : tqdm-like, optional
        Advanced per instance solved; its ``total`` set to the representatives' count once known.

    Returns
    -------
    RadiusTable
    """
    if not isinstance(options, RadiusTableOptions):
        raise TypeError(f"options: expected a RadiusTableOptions, got {type(options).__name__}")
    form, L_max, eps_min, pruning = options
    _check_inputs(form, system, L_max)
    t0 = time.perf_counter()
    if not formulation(form).tubes and any(z.n_vertices != c.n_vertices for z, c in zip(Z, decomp.cells)):
        # no Z in a form without tubes (open loop): q_k(0) are the cell's own vertices, not a chamfer Z's
        Z = cross_sections(decomp, "cell", 1.0)
    W0 = unit_disturbance(system.W)[0]
    cand = build_candidates(decomp, zero_disturbance_system(system), int(L_max), pruning)
    table = RadiusTable(decomp, system, tuple(Z), W0, form, int(L_max), float(eps_min), *_unsolved(cand))
    K = len(table.src)
    t1 = time.perf_counter()
    probs = table.problems(np.arange(K))
    if pruning and K:
        table.rep = TranslationClasses(decomp, system).representatives(table.src, table.dst, table.obstacle, probs)
    own = np.flatnonzero(table.rep == np.arange(K))         # the representatives: solved
    probs = [probs[k] for k in own]
    if progress is not None and hasattr(progress, "total"):
        progress.total = len(probs)                     # the bar's total: the instances solved
        if hasattr(progress, "refresh"):
            progress.refresh()
    t2 = time.perf_counter()
    if isinstance(solver, str) and solver == "highs":
        _solve_with_highs(table, own, probs, workers, progress)
        compile_s = 0.0
    else:
        compile_s = _solve_with_engine(table, own, probs, solver, workers, progress)
    for a in (table.value, table.lower, table.upper, table.status, table.provenance, table.exact):
        a[:] = a[table.rep]                             # translates: their representative's values
    for a in (table.value, table.lower):
        a[np.isnan(a)] = -np.inf                        # unknown: counts only in the rigorous upper bound
    table.upper[np.isnan(table.upper)] = np.inf
    t3 = time.perf_counter()
    table.status = table.status.astype(str)
    table.provenance = table.provenance.astype(str)
    table.stats.update({
        "form": form, "L_max": int(L_max), "n_instances": K, "n_pairs": len(np.unique(table._key(table.src, table.dst))),
        "solver": solver if isinstance(solver, str) else "pdhg", "candidate_seconds": t1 - t0,
        "problem_seconds": t2 - t1, "solve_seconds": t3 - t2 - compile_s, "compile_seconds": compile_s,
        "seconds": t3 - t0 - compile_s, "pruned": cand.pruned,
        "status_counts": {str(s): int(n) for s, n in zip(*np.unique(table.status, return_counts=True))},
        "n_translated": int(K - len(own)),
    })
    return table


def _unsolved(cand) -> tuple:
    """The per-instance columns of a :class:`RadiusTable` (``src, dst, L, obstacle``, then values, bounds,
    statuses, provenances and exact values not yet known) for the candidates ``cand``, sorted by
    ``(src, dst, L)``."""
    kk, LL = np.nonzero(cand.keep)
    order = np.lexsort((LL, cand.dst[kk], cand.src[kk]))
    kk, LL = kk[order], LL[order] + 1
    K = len(kk)
    return (cand.src[kk].copy(), cand.dst[kk].copy(), LL.astype(int), cand.obstacle[kk].copy(), np.full(K, np.nan),
            np.full(K, np.nan), np.full(K, np.nan), np.full(K, "", dtype=object), np.full(K, "", dtype=object),
            np.full(K, np.nan))


def _solve_with_highs(table: RadiusTable, own: np.ndarray, probs: list, workers, progress) -> None:
    """Fill ``table`` at the representatives ``own`` with one HiGHS solve of each of ``probs`` (the reference)."""
    vals = np.array(highs_map(_rho_highs, [(p, table.form) for p in probs], workers), float)
    if progress is not None:
        progress.update(len(probs))
    table.value[own], table.lower[own], table.upper[own], table.exact[own] = vals, vals, vals, vals
    table.status[own] = np.where(vals >= 0, "optimal", np.where(vals < 0, "infeasible", "numerical"))
    table.provenance[own] = "highs"


def _form_label(engine, method: str, expected) -> str:
    """What the batched ``engine`` solves, for messages: the LP of the record holding its form; a form equal to
    ``expected`` (``method``'s radius form) but another object is said to be a copy."""
    form = getattr(engine, "form", None)
    if not isinstance(form, PdhgForm):
        return f"a {type(engine).__name__} without a form"
    radius = " (radius form)" * bool(form.radius)
    if form == expected:
        return f"{method!r}{radius}, another object than the record's own form"
    try:
        return f"{formulation_of_form(form).name!r}{radius}"
    except TypeError:
        return f"a form{radius} no registered LP holds"


def _solve_with_engine(table: RadiusTable, own: np.ndarray, probs: list, solver, workers, progress) -> float:
    """Fill ``table`` at the representatives ``own`` with the batched engine ``solver`` (``'pdhg'``: a new one; else
    one on the record's own radius form), HiGHS deciding what it leaves unsettled; returns the compile seconds."""
    if isinstance(solver, str) and solver != "pdhg":
        raise ValueError(f"solver: expected 'pdhg', 'highs' or a PdhgBatchSolver, got {solver!r}")
    engine = pdhg_solver(table.form, radius=True) if isinstance(solver, str) else solver
    expected = formulation(table.form).radius.pdhg
    if expected is None or getattr(engine, "form", None) is not expected:
        raise ValueError(f"solver: expected the batched engine on the {table.form!r} LP's radius form "
                         f"(pdhg_solver({table.form!r}, radius=True)), got {_form_label(engine, table.form, expected)}")
    c0 = engine.stats["compile_seconds"]
    res = engine.optimise(probs, progress=progress)
    compile_s = engine.stats["compile_seconds"] - c0
    table.value[own], table.lower[own], table.upper[own] = res.value, res.lower, res.upper
    table.status[own], table.provenance[own] = res.status, res.provenance
    hi = own[np.asarray(res.provenance) == "highs"]       # not batched: HiGHS's exact value
    table.exact[hi] = table.value[hi]
    table.stats["iterations_median"] = float(np.median(res.iterations)) if len(own) else 0.0
    open_ = own[~np.isin(table.status[own], ("optimal", "infeasible")) & np.isnan(table.exact[own])]
    if open_.size:                                  # unsettled: HiGHS decides
        at = {k: a for a, k in enumerate(own.tolist())}
        vals = np.array(highs_map(_rho_highs, [(probs[at[k]], table.form) for k in open_.tolist()], workers), float)
        ok = ~np.isnan(vals)                        # a HiGHS failure keeps the engine's bracket
        k = open_[ok]
        table.value[k], table.lower[k], table.upper[k], table.exact[k] = (vals[ok],) * 4
        table.provenance[k] = "highs"
    table.stats["n_unsettled_to_highs"] = int(open_.size)
    return compile_s
