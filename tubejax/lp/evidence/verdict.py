"""Verdicts: what a solver answers for one problem, and the HiGHS confirmation step.

Every method (tube LP, open-loop LP) confirms an edge the same way: HiGHS
solves the margin form, and the returned evidence must pass the method's own
independent float64 checker at :data:`VERIFY_TOL`. On top of that, the evidence
is proved in exact rational arithmetic where possible (docs/math/evidence.md#proof-levels;
:func:`tubejax.lp.evidence.prove_with_basis`): a confirmed verdict carries
its :class:`~tubejax.lp.evidence.Proof`, and when an exact vertex rebuilt from
HiGHS's basis replaced the float evidence, the verdict's evidence is that vertex
rounded to float64 (it passes the float64 check too).
"""

from __future__ import annotations

import logging
import time
from functools import partial
from typing import Callable, NamedTuple, Sequence

import numpy as np

from .registry import FORMULATIONS, formulation
from ...model.problem import TubeProblem
from ..engines.highs import solve_margin_lp
from ..engines.certify import MARGIN_SAFETY
from .decide import EXACT_BAND, Refutation, decide_exactly, float_dual_bound
from .prove import prove_evidence, prove_with_basis, settle

__all__ = ["Verdict", "Pending", "VERIFY_TOL", "CLEAR_MARGIN", "confirm_with_highs", "verdict_of_result",
           "clear_edge", "unproved_verdict_of_result",
           "evidence_margin", "highs_verdict", "sequential_solver", "highs_solver", "highs_solve_batch",
           "TRANSLATE_EDGE", "TRANSLATED_PROOF", "stamped"]

log = logging.getLogger("tubejax")

#: Max violation (unit rows, float64) that confirms stored evidence (docs/math/evidence.md).
VERIFY_TOL = 1e-9
#: The margin beyond which HiGHS's optimum is clear of zero (``min_margin`` 0): an optimum above it whose
#: evidence passes the float check is an edge even when its proof stays at the float level
#: (:func:`clear_edge`; at or below it an edge needs an exact proof); a solve whose optimum is at least
#: ``-CLEAR_MARGIN`` reports its basis (``basis_min_margin``), from which the exact steps start.
CLEAR_MARGIN = 1e-6


def _standard_check(violation: Callable) -> bool:
    """Whether ``violation`` is a registered LP's own float check, whose value
    :func:`~tubejax.lp.evidence.prove_with_basis` reports as is."""
    return any(violation is f.violation for f in FORMULATIONS.values())


#: Tried in turn when HiGHS's default (dual simplex) does not reach ``Optimal``: on some
#: feasible, bounded margin LPs (a tiny entry in ``B``, ``W = {0}``) HiGHS 1.16's dual simplex
#: stops with status ``Unknown``, and the pair would wrongly lose that horizon.
_RETRY_OPTIONS = ({"simplex_strategy": 4}, {"solver": "ipm"})        # primal simplex, then IPM

#: Provenance of a verdict HiGHS gave alone because an exact translate of the problem is a likely
#: edge (:mod:`tubejax.abstraction.translation_classes`): PDHG would only find it feasible again.
TRANSLATE_EDGE = "highs-translate"
#: Provenance of an edge proved by exact translation: the exact tube of its class's canonical
#: problem (HiGHS-confirmed, proved exactly), moved by the edge's exact offset and checked exactly
#: against its own data (:mod:`tubejax.lp.evidence.translate_verdicts`); no HiGHS solve of its own.
TRANSLATED_PROOF = "exact-translate"


def stamped(verdict, provenance: str):
    """``verdict`` with the provenance of the path that asked for it, unless it names its own proof
    (:data:`TRANSLATED_PROOF`)."""
    return verdict if verdict.provenance == TRANSLATED_PROOF else verdict._replace(provenance=provenance)


class Verdict(NamedTuple):
    """A solver's answer for one problem.

    status : ``'edge'`` (confirmed), ``'infeasible'`` or ``'unconfirmed'``
    margin : ``t*`` (nan when unknown)
    tube : the confirmed evidence (a Tube, an OpenLoopPlan, ...; ``None`` unless ``'edge'``)
    provenance : which path decided (``'highs'``, ``'pdhg+highs'``, ...)
    proof : the evidence's :class:`~tubejax.lp.evidence.Proof` (``None`` unless ``'edge'``,
        or when the solver did not prove it)
    refutation : a refusal's evidence, :class:`~tubejax.lp.evidence.decide.Refutation`
        (``None`` for an edge)
    exact_seconds : seconds spent deciding it in exact arithmetic (0 when floats decided)
    """

    status: str
    margin: float
    tube: object
    provenance: str
    proof: object = None
    refutation: object = None
    exact_seconds: float = 0.0


class Pending:
    """A likely edge whose HiGHS confirmation is still running.

    A batched solver returns it (when asked to defer) for an instance whose own
    primal point already satisfies Problem 2 in float64; it is not an edge until
    :meth:`result` says so.

    Parameters
    ----------
    future : concurrent.futures.Future resolving to the HiGHS :class:`Verdict`
    provenance : str
    on_result : callable, optional
        Called once, in the thread that first asks for the result, with the verdict
        (solvers count confirmations with it).
    """

    def __init__(self, future, provenance: str, on_result: Callable | None = None):
        self.future = future
        self.provenance = provenance
        self._on_result = on_result
        self._verdict: Verdict | None = None

    def done(self) -> bool:
        return self.future.done()

    def result(self) -> Verdict:
        """The confirmed verdict (blocks until HiGHS is done)."""
        if self._verdict is None:
            self._verdict = stamped(self.future.result(), self.provenance)
            if self._on_result is not None:
                self._on_result(self._verdict)
        return self._verdict


def evidence_margin(lp, evidence) -> float:
    """The margin ``min(g - G x)`` (capped at ``t_max``) that ``evidence`` achieves in the margin
    form ``lp`` (a :class:`~tubejax.lp.declarations.tube_lp.TubeLP` or open-loop LP), float64."""
    x = lp.index.pack(evidence)
    return float(min(np.min(lp.g - lp.G @ x), lp.t_max))


def confirm_with_highs(prob: TubeProblem, build: Callable, violation: Callable,
                       provenance: str) -> Verdict:
    """Solve ``build(prob)`` with HiGHS and check the evidence with ``violation``
    (:func:`verdict_of_result`; the dual simplex, then :data:`_RETRY_OPTIONS`).

    ``'edge'`` when HiGHS is optimal and ``violation(prob, evidence) <= VERIFY_TOL``, its
    evidence proved exactly where possible (``proof`` says at which level); ``'infeasible'``
    when the optimal margin is negative; ``'unconfirmed'`` otherwise. With ``prob.min_margin =
    m > 0`` a margin below ``m`` is ``'infeasible'``, and an edge's final evidence must achieve
    ``m - VERIFY_TOL`` in float64 (:func:`evidence_margin`), else ``'unconfirmed'``.
    """
    lp = build(prob)
    return verdict_of_result(prob, lp, solve_margin_lp(lp, basis_min_margin=-CLEAR_MARGIN), violation, provenance)


def verdict_of_result(prob, lp, res, violation: Callable, provenance: str, snapped_check=None,
                      first=None, viol: float | None = None) -> Verdict:
    """The verdict of :func:`confirm_with_highs` from HiGHS's first answer ``res`` for ``lp``
    (``snapped_check``, ``first``: see :func:`~tubejax.lp.evidence.prove.prove_with_basis`;
    ``viol``: ``violation`` of HiGHS's point, when the caller has it).

    Floating point decides only where it can (docs/math/margins.md#zero-margin-edges; ``min_margin`` 0):

    * an optimal margin above :data:`~tubejax.lp.evidence.decide.EXACT_BAND` whose evidence passes
      the float64 check is an edge (proved exactly where possible; a float-level proof only
      above :data:`CLEAR_MARGIN`: a :func:`clear_edge`);
    * an optimal margin below ``-EXACT_BAND`` whose duals give a float64 weak-duality bound below
      ``-MARGIN_SAFETY`` (:func:`~tubejax.lp.evidence.decide.float_dual_bound`) is a non-edge,
      the bound its evidence;
    * everything else -- margins within the band, failed checks, HiGHS without an optimum -- is
      decided in exact arithmetic (:func:`~tubejax.lp.evidence.decide.decide_exactly`), so the
      verdict never follows the sign of a rounding error, nor which options or start HiGHS had.
    """
    m = float(getattr(prob, "min_margin", 0.0))
    first_res = res
    for options in _RETRY_OPTIONS:
        if res.status == "Optimal":
            break
        res = solve_margin_lp(lp, options, basis_min_margin=-CLEAR_MARGIN)
    if m > 0:
        return _verdict_min_margin(prob, lp, res, violation, provenance, snapped_check, first,
                                   viol if res is first_res else None)
    if res.status == "Optimal":
        if res.margin > EXACT_BAND:
            evidence = lp.index.split(res.x)
            if viol is None or res is not first_res:
                viol = violation(prob, evidence)
            if viol <= VERIFY_TOL:
                evidence, proof = _prove(prob, lp, res, evidence, violation, viol, snapped_check, first)
                if proof.level == "exact" or _clear_margin(res):
                    return Verdict("edge", res.margin, evidence, provenance, proof)
        elif res.margin < -EXACT_BAND:
            b = float_dual_bound(lp, res)
            if b < -MARGIN_SAFETY:
                return Verdict("infeasible", res.margin, None, provenance, None, Refutation("dual", b))
    if res.status == "Optimal" and res.col_status is None:
        res, viol = solve_margin_lp(lp, basis_min_margin=-np.inf), None    # the exact steps start from its basis
    if res is not first_res:
        viol = None
    return _exact_verdict(prob, lp, res, violation, provenance, snapped_check, first, viol)


def _clear_margin(res) -> bool:
    """Whether HiGHS's answer ``res`` is optimal with a margin above :data:`CLEAR_MARGIN`."""
    return res.status == "Optimal" and res.margin > CLEAR_MARGIN


def clear_edge(prob, lp, res, violation: Callable) -> tuple[bool, float | None]:
    """Whether HiGHS's answer ``res`` for ``prob``'s margin form ``lp`` is a clear edge: ``min_margin`` 0,
    optimal with a margin above :data:`CLEAR_MARGIN`, its point passing ``violation`` at
    :data:`VERIFY_TOL` -- an edge for :func:`verdict_of_result` whatever its proof's level.

    Returns ``(clear, viol)``: ``viol`` is the float check of HiGHS's point (``None`` when not computed).
    """
    if not (float(getattr(prob, "min_margin", 0.0)) == 0.0 and _clear_margin(res)):
        return False, None
    viol = violation(prob, lp.index.split(res.x))
    return viol <= VERIFY_TOL, viol


def unproved_verdict_of_result(prob, lp, res, violation: Callable, provenance: str) -> Verdict:
    """:func:`verdict_of_result`, for callers that use only refutations (the product path's projections):
    a :func:`clear_edge` is ``'unconfirmed'`` (HiGHS's margin, no evidence) instead of being proved;
    every other answer gets :func:`verdict_of_result`'s verdict."""
    clear, viol = clear_edge(prob, lp, res, violation)
    if clear:
        return Verdict("unconfirmed", res.margin, None, provenance)
    return verdict_of_result(prob, lp, res, violation, provenance, viol=viol)


def _exact_verdict(prob, lp, res, violation: Callable, provenance: str, snapped_check=None, first=None,
                   viol: float | None = None) -> Verdict:
    """:func:`~tubejax.lp.evidence.decide.decide_exactly` as a :class:`Verdict` (``viol``: the float
    check of HiGHS's point, when known), with its ``exact_seconds``."""
    t0 = time.perf_counter()
    margin = res.margin if res.status == "Optimal" else float("nan")
    d = decide_exactly(prob, lp, res, None, viol, snapped_check, first)
    if d.status == "edge":
        evidence, proof = d.evidence, d.proof
        if proof.exact is not None:
            evidence, proof = settle(proof, evidence)
        # a primal proof's violation is already the float check of what is stored (prove_with_basis)
        v = proof.violation if d.how == "primal proof" and _standard_check(violation) else \
            violation(prob, evidence)
        if not v <= VERIFY_TOL:                 # the float rounding of an exact tube: keep the exact one
            log.warning("%s: the exact evidence rounded to float64 violates by %.3e", provenance, v)
        proof = proof._replace(violation=v, note=f"decided exactly ({d.how}): {proof.note}")
        out = Verdict("edge", max(margin, 0.0) if np.isfinite(margin) else 0.0, evidence, provenance, proof)
    elif d.status == "infeasible":
        out = Verdict("infeasible", min(margin, d.refutation.bound) if np.isfinite(margin) else d.refutation.bound,
                      None, provenance, None, d.refutation)
    else:
        out = Verdict("unconfirmed", margin, None, provenance, None, d.refutation)
    return out._replace(exact_seconds=time.perf_counter() - t0)


def _verdict_min_margin(prob, lp, res, violation, provenance, snapped_check, first, viol) -> Verdict:
    """With ``min_margin = m > 0`` (an edge needs ``t* >= m`` on unit rows (docs/math/margins.md), whose
    norms may be irrational): HiGHS's optimum against ``m``, the evidence checked in float64
    (``viol``: the float check of ``res``'s point, when known)."""
    m = float(getattr(prob, "min_margin", 0.0))
    if res.status != "Optimal":
        return Verdict("unconfirmed", float("nan"), None, provenance)
    if res.margin < m:          # feasible, perhaps, but short of the demanded margin: no edge at this L
        return Verdict("infeasible", res.margin, None, provenance, None, Refutation("dual", res.margin,
                       note=f"HiGHS's optimum below min_margin {m:g}"))
    evidence = lp.index.split(res.x)
    if viol is None:
        viol = violation(prob, evidence)
    if viol <= VERIFY_TOL:
        evidence, proof = _prove(prob, lp, res, evidence, violation, viol, snapped_check, first)
        if not evidence_margin(lp, evidence) >= m - VERIFY_TOL:
            log.warning("%s: HiGHS margin %.3e >= min_margin %g but the evidence achieves %.3e: not "
                        "confirmed", provenance, res.margin, m, evidence_margin(lp, evidence))
            return Verdict("unconfirmed", res.margin, None, provenance)
        return Verdict("edge", res.margin, evidence, provenance, proof)
    log.warning("%s: HiGHS margin %.3e >= %g but the evidence violates by %.3e: not confirmed",
                provenance, res.margin, m, viol)
    return Verdict("unconfirmed", res.margin, None, provenance)


def _prove(prob, lp, res, evidence, violation: Callable, viol: float, snapped_check=None, first=None):
    """The exact proof of confirmed evidence, ``(evidence, proof)``: a rational vertex that
    replaced the float evidence is returned as its float64 rounding
    (:func:`~tubejax.lp.evidence.settle`), which must pass ``violation`` at :data:`VERIFY_TOL`
    too (otherwise the original evidence is kept, at the float level)."""
    proof = prove_with_basis(prob, lp, res, evidence, viol, snapped_check, first)
    if proof.level != "exact":                   # a fresh HiGHS may end in a better basis
        again = prove_evidence(prob, evidence, resolve=True)
        proof = again if again.level == "exact" else proof
    if proof.exact is None:
        return evidence, proof._replace(violation=viol)
    rounded, settled = settle(proof, evidence)
    # the proof's violation is already the standard check of that rounding (prove_with_basis)
    v = proof.violation if _standard_check(violation) else violation(prob, rounded)
    if v <= VERIFY_TOL:
        return rounded, settled._replace(violation=v)
    log.warning("the exact evidence rounded to float64 violates by %.3e: kept the float evidence", v)
    return evidence, proof._replace(level="float", violation=viol, exact=None,
                                    note=proof.note + "; its float64 rounding fails the float check")


def highs_verdict(prob: TubeProblem, provenance: str | None = None, form: str = "tube") -> Verdict:
    """:func:`confirm_with_highs` of one problem of the LP ``form``, with its record's
    (:func:`~tubejax.lp.evidence.registry.formulation`) dense model, float check and (by default)
    provenance."""
    f = formulation(form)
    return confirm_with_highs(prob, f.build, f.violation, f.provenance if provenance is None else provenance)


def sequential_solver(verdict: Callable[[TubeProblem], Verdict]) -> Callable:
    """A batch solver that calls ``verdict`` on each problem in turn.

    Returns
    -------
    callable
        ``solve_batch(problems, progress=None) -> list[Verdict]``; ``progress.update(1)``
        is called after each problem. Its ``verdict`` attribute is ``verdict``.
    """
    def solve_batch(problems: Sequence[TubeProblem], progress=None) -> list:
        out = []
        for p in problems:
            out.append(verdict(p))
            if progress is not None:
                progress.update(1)
        return out

    name = getattr(verdict, "__name__", None) or getattr(getattr(verdict, "func", None), "__name__", "verdict")
    solve_batch.__doc__ = f"One ``{name}`` per problem (see :func:`sequential_solver`)."
    solve_batch.verdict = verdict
    return solve_batch


#: The reference batch solver of each LP, made once (:func:`highs_solver`).
_HIGHS_SOLVERS: dict = {}


def highs_solver(form: str = "tube") -> Callable:
    """The reference batch solver of the LP ``form``: one :func:`highs_verdict` per problem.

    The same object for the same ``form``; it declares its method (``solver.method == form``, read by
    :func:`~tubejax.abstraction.methods.solver_method`).
    """
    if form not in _HIGHS_SOLVERS:
        formulation(form)                       # a known LP
        solver = sequential_solver(partial(highs_verdict, form=form))
        solver.method = form
        solver.__name__ = f"highs_solver({form!r})"
        _HIGHS_SOLVERS[form] = solver
    return _HIGHS_SOLVERS[form]


#: The reference batch solver of the tube LP: one HiGHS solve per problem.
highs_solve_batch = highs_solver("tube")
