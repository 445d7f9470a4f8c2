"""HiGHS confirmations of many exact translates of one problem, together.

The translation classes of :mod:`tubejax.translations` send the translates of a likely edge
straight to HiGHS. Confirmed one by one (:func:`~tubejax.lp.evidence.verdict.confirm_with_highs`)
each costs a cold simplex solve and a rational proof. Confirmed together, as here, three
things are shared, none of which changes what decides a verdict:

* **HiGHS warm-started.** Translates have the same LP matrix; only right-hand sides and
  bounds move. Each solve starts from the optimal basis of the one before
  (:class:`~tubejax.lp.solvers.highs.WarmMarginSolver`) and usually ends after 0 simplex
  iterations. A warm margin within :data:`WARM_COLD_BAND` of 0 is solved again cold: there
  the sign decides, HiGHS's last bits depend on where it started, and the verdict must be
  the one the one-by-one confirmation gives.
* **One exact check for many candidates.** The first proof candidate of every problem with
  a positive margin (its HiGHS point with the nonbasic variables on their bounds) is checked
  in one pass (:func:`~tubejax.lp.evidence.check_batch.exact_tube_violations`).
* **Proofs translated.** At a zero margin the first candidate is HiGHS's point rebuilt in
  rationals, which is slow. Once one problem of the group is proved exactly, its exact tube
  translated by the exact offset of another problem's source cell is that problem's first
  candidate (the translate of a feasible tube is feasible for the translated problem,
  :mod:`tubejax.translations`); these too are checked in one pass.

Every candidate is only a proposal: the exact check against the problem's own rational data
is the proof, and a problem whose candidate fails goes through the whole one-by-one proof.
"""

from __future__ import annotations

import threading
from typing import Callable, Sequence

from ..formulations.tube.dense import build_tube_lp, tube_violation
from ..solvers.highs import WarmMarginSolver, solve_margin_lp
from .check import ExactTube
from .prove import TIGHT_MARGIN, snapped_float_candidate
from .rational import QArray
from .verdict import _CLEAR_MARGIN, verdict_of_result

__all__ = ["confirm_translates_with_highs", "highs_translate_verdicts", "WARM_COLD_BAND"]

#: A warm-started margin within this of 0 (or a warm solve that is not optimal) is solved again
#: cold, so that the verdict is the one :func:`~tubejax.lp.evidence.verdict.confirm_with_highs` gives.
WARM_COLD_BAND = 1e-9

_local = threading.local()

_TRANSLATED = "exact tube of a translate, translated"


def _warm() -> WarmMarginSolver:
    w = getattr(_local, "solver", None)
    if w is None:
        w = _local.solver = WarmMarginSolver()
    w.reset()                       # each call on its own: its answers never depend on an earlier call
    return w


def _solve_all(lps: list) -> list:
    warm = _warm()
    out = []
    cold = False              # translates share their optimal margin: after one near 0, go cold at once
    for lp in lps:
        res = None if cold else warm.solve(lp, basis_min_margin=-_CLEAR_MARGIN)
        if res is None or not (res.status == "Optimal" and abs(res.margin) > WARM_COLD_BAND):
            res = solve_margin_lp(lp, basis_min_margin=-_CLEAR_MARGIN)
            cold = res.status == "Optimal" and abs(res.margin) <= WARM_COLD_BAND
        out.append(res)
    return out


def _checked(exact_batch: Callable, problems: Sequence, ks: list, cands: list) -> dict:
    """``{k: exact check}`` of ``cands[i]`` for ``problems[ks[i]]`` in one pass (empty when the
    batch refuses: each is then checked on its own, and says why)."""
    if not ks:
        return {}
    try:
        return dict(zip(ks, exact_batch([problems[k] for k in ks], cands)))
    except (ValueError, ArithmeticError):
        return {}


def _translated(tube, src_from, src_to):
    """``tube`` (a float Tube or ExactTube) moved by the exact offset between the first vertices
    of two source cells (``p -> p + c``; ``eps`` and ``u`` unchanged), as an ExactTube."""
    t = ExactTube.coerce(tube)
    c = QArray.from_floats(src_to.vertices[0]) - QArray.from_floats(src_from.vertices[0])
    return ExactTube(t.p + c[None, :], t.eps, t.u)


def confirm_translates_with_highs(problems: Sequence, build: Callable, violation: Callable, provenance: str,
                                  exact_batch: Callable | None = None, build_many: Callable | None = None,
                                  violations: Callable | None = None) -> list:
    """:func:`~tubejax.lp.evidence.verdict.confirm_with_highs` of each of ``problems``, done
    together (see the module doc).

    Parameters
    ----------
    problems : sequence of TubeProblem, length K
        Meant for exact translates of one problem; any problems are answered correctly
        (another matrix is solved cold, a failed candidate is proved one by one).
    build, violation : callables
        The formulation's dense builder and float64 checker.
    provenance : str
    exact_batch : callable, optional
        ``exact_batch(problems, candidates) -> list of Fraction``; without it every proof is
        made one by one.
    build_many, violations : callables, optional
        ``build`` and ``violation`` for many problems at once (``build_many(problems) -> list``,
        ``violations(problems, evidence) -> ndarray``), with the same results.

    Returns
    -------
    list of Verdict, length K, in order
    """
    K = len(problems)
    lps = build_many(problems) if build_many is not None else [build(p) for p in problems]
    results = _solve_all(lps)
    mins = [float(getattr(p, "min_margin", 0.0)) for p in problems]
    ok = [r.status == "Optimal" and r.margin >= m for r, m in zip(results, mins)]
    viols: dict = {}
    if violations is not None:
        ks = [k for k in range(K) if ok[k]]
        viols = dict(zip(ks, violations([problems[k] for k in ks], [lps[k].index.split(results[k].x) for k in ks])))
    snapped: dict = {}
    if exact_batch is not None:
        ks, cands = [], []
        for k in range(K):
            c = snapped_float_candidate(lps[k], results[k]) if ok[k] else None
            if c is not None:
                ks.append(k)
                cands.append(c)
        fv = violations([problems[k] for k in ks], cands) if violations is not None and ks else [None] * len(ks)
        snapped = {k: (ev, fv[ks.index(k)]) for k, ev in _checked(exact_batch, problems, ks, cands).items()}
    out: list = [None] * K
    tight = {k for k in range(K) if ok[k] and not results[k].margin > TIGHT_MARGIN}
    ref = None                                          # (k, exact tube) of a proved zero-margin edge
    for k in range(K):
        if k not in tight or ref is None:
            out[k] = verdict_of_result(problems[k], lps[k], results[k], violation, provenance, snapped.get(k),
                                       viol=viols.get(k))
            v = out[k]
            if k in tight and v.status == "edge" and v.proof is not None and v.proof.level == "exact":
                ref = (k, v.proof.exact if isinstance(v.proof.exact, ExactTube) else v.tube)
    rest = [k for k in sorted(tight) if out[k] is None]       # only once ``ref`` is set
    if rest and exact_batch is not None:
        k0, tube = ref
        cands = [_translated(tube, problems[k0].source, problems[k].source) for k in rest]
        checks = _checked(exact_batch, problems, rest, cands)
        firsts = {k: (c, checks[k], _TRANSLATED) for k, c in zip(rest, cands) if k in checks}
    else:
        firsts = {}
    for k in rest:
        out[k] = verdict_of_result(problems[k], lps[k], results[k], violation, provenance, first=firsts.get(k),
                                   viol=viols.get(k))
    return out


def highs_translate_verdicts(problems: Sequence, provenance: str = "highs") -> list:
    """:func:`~tubejax.lp.evidence.verdict.highs_verdict` of each of ``problems`` (exact translates
    of one tube problem), done together (:func:`confirm_translates_with_highs`)."""
    from ..formulations.tube.dense_batch import build_tube_lps, tube_violations
    from .check_batch import exact_tube_violations
    return confirm_translates_with_highs(problems, build_tube_lp, tube_violation, provenance,
                                         exact_tube_violations, build_tube_lps, tube_violations)
