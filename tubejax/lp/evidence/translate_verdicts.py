"""HiGHS confirmations of many exact translates of one problem, together.

The translation classes (:mod:`tubejax.abstraction.translation_classes`) send the translates of a
likely edge straight to HiGHS. Here four things are shared, none of which changes what decides a
verdict:

* **HiGHS warm-started.** Translates have the same LP matrix, and the translate of an optimal
  basis is optimal: the class's *canonical problem* (:func:`canonical_problem`, the same for every
  member bit for bit) is solved cold once, each member from its optimal basis
  (:func:`~tubejax.lp.engines.highs.solve_margin_lp_from`). A margin within
  :data:`WARM_COLD_BAND` of 0 is solved cold: there the sign decides, and the verdict must be the
  one-by-one one.
* **One exact check for many candidates** (:mod:`~tubejax.lp.evidence.check_batch`,
  :mod:`~tubejax.lp.declarations.tube_lp_batch`).
* **Proofs translated.** At a zero margin the canonical problem's exact tube moved by a member's
  exact offset is that member's first candidate.
* **Edges proved by exact translation**: the canonical problem's exact tube, moved by a member's
  exact offset, checked exactly against the member's own data, makes it an edge with provenance
  :data:`~tubejax.lp.evidence.verdict.TRANSLATED_PROOF`
  (docs/math/evidence.md#the-exact-check-of-a-translated-tube).

Every answer depends on the member and its class only, never on which other members share the
job. Every candidate is only a proposal: the exact check against the problem's own rational data
is the proof, and a member whose candidate fails goes through the whole one-by-one proof.
"""

from __future__ import annotations

from typing import Callable, NamedTuple, Sequence

import numpy as np

from ...model.geometry import Polytope
from ...model.system import group_shift
from .registry import formulation
from ..declarations.tube_families import translation_groups
from ..declarations.tube_lp import build_tube_lp, tube_violation
from ..declarations.tube_variables import Tube
from ...model.problem import TubeProblem
from ..declarations.tube_lp_batch import build_tube_lps, same_tube_rows, tube_violations
from ..engines.highs import solve_margin_lp, solve_margin_lp_from
from .check import ExactTube
from .check_batch import exact_tube_violations, rows_equal, translated_tube_violations
from .decide import EXACT_BAND
from .prove import TIGHT_MARGIN, Proof, snapped_float_candidate
from .rational import QArray
from .verdict import CLEAR_MARGIN, TRANSLATED_PROOF, VERIFY_TOL, Verdict, verdict_of_result

__all__ = ["TranslateChecks", "TUBE_CHECKS", "confirm_translates_with_highs", "highs_translate_verdicts",
           "canonical_problem", "translated_proofs", "system_translation_groups", "WARM_COLD_BAND"]

#: A warm-started margin within this of 0 (or a warm solve that is not optimal) is solved again
#: cold, so that the verdict is the one :func:`~tubejax.lp.evidence.verdict.confirm_with_highs` gives.
WARM_COLD_BAND = 1e-9

_TRANSLATED = "the canonical problem's exact tube, translated"

#: With ``min_margin > 0``, the canonical margin must clear it by this for translated proofs (the
#: members' own float margins may differ from it by rounding).
_MIN_MARGIN_BAND = 1e-9


def canonical_problem(prob):
    """``prob`` moved by a translation its row families are invariant under (``A`` leaves it
    fixed) so that its source's first vertex lies at 0 on each group of axes' first axis, and the
    offset it was moved by, ``(problem, shift (n,))``.

    The exact translates of one problem (one translation class) all have the same canonical
    problem, bit for bit: each vertex becomes the rounding of one exact difference, and ``H``,
    ``h`` and the box follow from those. It serves only as a start and as a proof candidate,
    which each member's own data then decide.
    """
    shift = _shift(prob)

    def moved(P):
        V = P.vertices - shift
        return Polytope(V, P.H, np.max(V @ P.H.T, axis=0))

    lo, hi = prob.box
    return TubeProblem(prob.system, moved(prob.source), moved(prob.target), moved(prob.safe), prob.Z, int(prob.L),
                       (lo - shift, hi - shift), prob.eps_min, prob.min_margin), shift


_GROUPS: dict = {}


def _shift(prob) -> np.ndarray:
    """The offset :func:`canonical_problem` moves ``prob`` by, shape ``(n,)``
    (:func:`~tubejax.model.system.group_shift` of its source's first vertex)."""
    return group_shift(prob.source.vertices[0], system_translation_groups(prob.system))


def system_translation_groups(system) -> np.ndarray:
    """:func:`~tubejax.lp.declarations.tube_families.translation_groups` of ``system`` (cached)."""
    hit = _GROUPS.get(id(system))
    if hit is None or hit[0] is not system:
        hit = _GROUPS[id(system)] = (system, translation_groups(system))
    return hit[1]


def _same_data(a, b) -> bool:
    """Whether two tube problems hold the same float data (so the same LP), bit for bit."""
    return (np.array_equal(a.box[0], b.box[0]) and np.array_equal(a.box[1], b.box[1])
            and all(np.array_equal(getattr(a, f).vertices, getattr(b, f).vertices)
                    and np.array_equal(getattr(a, f).h, getattr(b, f).h) for f in ("source", "target", "safe")))


def _start(problems, lps, build: Callable):
    """The canonical problem's HiGHS answer (cold, as one by one; with its basis when its margin is
    at least ``-1e-6``), the canonical problem, the first member's shift and the canonical LP:
    ``(result, problem, shift, lp)``, or ``None`` (then every member is solved cold)."""
    try:
        canon, shift = canonical_problem(problems[0])
        same = not shift.any() and _same_data(canon, problems[0])     # its own canonical problem
        lp = lps[0] if same and lps[0] is not None else build(canon)
    except (ValueError, ArithmeticError):                  # e.g. a degenerate moved polytope
        return None
    return solve_margin_lp(lp, basis_min_margin=-CLEAR_MARGIN), canon, shift, lp


def _same_lp(prob, lp, start) -> bool:
    """Whether ``lp`` (of ``prob``) is the canonical LP, bit for bit (rows: the same sets' normals)."""
    if lp is start[3]:
        return True
    return (all(np.array_equal(getattr(lp, f), getattr(start[3], f)) for f in ("g", "lb", "ub", "g_hard"))
            and lp.t_max == start[3].t_max and same_tube_rows(prob, start[1]))


def _solve_all(problems, lps: list, start) -> list:
    """HiGHS's answer for each LP: from the canonical basis (if any, and its margin is not near
    0), else cold; a warm margin near 0 is solved again cold (see :data:`WARM_COLD_BAND`). An LP
    equal to the canonical one (a problem that is its own canonical problem) takes its answer."""
    out = []
    warm = (start is not None and start[0].status == "Optimal" and start[0].col_status is not None
            and abs(start[0].margin) > WARM_COLD_BAND)
    for prob, lp in zip(problems, lps):
        if start is not None and _same_lp(prob, lp, start):
            out.append(start[0])
            continue
        res = solve_margin_lp_from(lp, (start[0].col_status, start[0].row_status),
                                   basis_min_margin=-CLEAR_MARGIN) if warm else None
        if res is None or not (res.status == "Optimal" and abs(res.margin) > WARM_COLD_BAND):
            res = solve_margin_lp(lp, basis_min_margin=-CLEAR_MARGIN)
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


def _translated_many(tube, shifts: np.ndarray) -> list:
    """``tube`` (a float Tube or ExactTube) moved exactly by each row of ``shifts`` ``(K, n)``
    (``p -> p + shift``; ``eps`` and ``u`` unchanged and shared), list of K ExactTubes (the offsets
    made exact and added in one pass)."""
    t = ExactTube.coerce(tube)
    P = t.p[None] + QArray.from_floats(shifts)[:, None, :]            # (K, L, n)
    return [ExactTube(QArray(P.num[k], P.den), t.eps, t.u) for k in range(len(shifts))]


def _settled_many(tubes: list) -> list:
    """:func:`~tubejax.lp.evidence.prove.settle`'s ``(float evidence, exact or None)`` for
    translates of one tube (:func:`_translated_many`: ``eps`` and ``u`` shared), in one pass."""
    def rounding_exact(q: QArray):              # (rounding, whether it equals q, per leading index)
        f = q.to_float()
        return f, rows_equal(q, QArray.from_floats(f))

    Pf, p_exact = rounding_exact(QArray.concatenate([t.p[None] for t in tubes], axis=0))   # (K, L, n)
    (eps_f,), eps_exact = rounding_exact(tubes[0].eps[None])
    (u_f,), u_exact = rounding_exact(tubes[0].u[None])
    shared = bool(eps_exact[0] and u_exact[0])
    return [(Tube(Pf[k], eps_f, u_f), None if (p_exact[k] and shared) else t) for k, t in enumerate(tubes)]


def _proved_by_translation(problems, start, checks: "TranslateChecks", provenance: str) -> dict:
    """``{k: Verdict}`` of the members proved by the canonical problem's exact tube, translated
    (module doc; :func:`translated_proofs` from the canonical problem's verdict); the others are left out."""
    res, canon, _, lp = start
    if res.status != "Optimal":
        return {}
    return translated_proofs(canon, verdict_of_result(canon, lp, res, checks.violation, provenance), problems, checks)


def translated_proofs(reference, verdict: Verdict, problems: Sequence, checks: "TranslateChecks",
                      note: str = _TRANSLATED) -> dict:
    """``{k: Verdict}`` of the ``problems`` proved by ``reference``'s exact tube moved by their exact offset
    from it and checked exactly against their own data, then in float64 (provenance
    :data:`~tubejax.lp.evidence.verdict.TRANSLATED_PROOF`, ``verdict``'s margin); the others are left out.

    Parameters
    ----------
    reference : TubeProblem
        A solved problem: a class's canonical problem, or any member of it (a representative).
    verdict : Verdict
        ``reference``'s verdict; nothing is proved unless it is an edge with an exact proof.
    problems : sequence of TubeProblem, length K
        Meant for exact translates of ``reference``; a member whose offset from ``reference`` (the
        :func:`canonical_problem` shifts' difference) is not a float exactly, or whose check fails,
        is left out (it is solved on its own).
    checks : TranslateChecks
        ``exact_batch`` is required; ``exact_translated`` and ``violations`` are used when given.
    note : str
        The proofs' note (where the tube came from).

    Returns
    -------
    dict
        ``{k: Verdict}`` for the members proved.
    """
    _, violation, exact_batch, _, violations, exact_translated = checks
    ref = verdict
    if exact_batch is None or not isinstance(ref, Verdict) or ref.status != "edge" or ref.proof is None \
            or ref.proof.level != "exact" or not problems:
        return {}
    m = float(getattr(reference, "min_margin", 0.0))
    if m > 0 and not ref.margin > m + _MIN_MARGIN_BAND:
        return {}
    tube = ref.proof.exact if formulation("tube").is_exact(ref.proof.exact) else ref.tube
    try:
        every = group_shift(np.array([p.source.vertices[0] for p in problems]),
                            system_translation_groups(reference.system))   # (K, n)
    except ValueError:                                  # sources of other dimensions: no shared shift
        every = np.array([_shift(p) for p in problems])
    base = _shift(reference)                # 0 for a canonical problem
    whole = np.ones(len(problems), dtype=bool)    # offsets that are floats exactly
    if base.any():                          # the offsets from the reference, kept where exactly floats
        moved = every - base
        whole = rows_equal(QArray.from_floats(moved), QArray.from_floats(every) - QArray.from_floats(base)[None])
        every = moved
    ks = [k for k, p in enumerate(problems) if whole[k] and float(getattr(p, "min_margin", 0.0)) == m
          and not (not every[k].any() and _same_data(reference, p))]          # not the reference itself
    if not ks:
        return {}
    shifts = every[ks]
    cands = _translated_many(tube, shifts)
    found = {}
    if exact_translated is not None:
        same = exact_translated(reference, tube, [problems[k] for k in ks], shifts,
                                system_translation_groups(reference.system))
        found = {k: v for k, v in zip(ks, same) if v is not None}
    rest = [a for a, k in enumerate(ks) if k not in found]
    found.update(_checked(exact_batch, problems, [ks[a] for a in rest], [cands[a] for a in rest]))
    ok = [(k, cand) for k, cand in zip(ks, cands) if k in found and found[k] <= 0]
    passed = [(k, (ev, Proof("exact", 0.0, found[k], exact, note)))
              for (k, _), (ev, exact) in zip(ok, _settled_many([c for _, c in ok]) if ok else [])]
    if not passed:
        return {}
    if violations is not None:                  # the float re-check of the rounded tubes, in one pass
        fvs = violations([problems[k] for k, _ in passed], [ev for _, (ev, _) in passed])
    else:
        fvs = [violation(problems[k], ev) for k, (ev, _) in passed]
    return {k: Verdict("edge", ref.margin, ev, TRANSLATED_PROOF, proof._replace(violation=float(fv)))
            for (k, (ev, proof)), fv in zip(passed, fvs) if fv <= VERIFY_TOL}


class TranslateChecks(NamedTuple):
    """The functions that build and check the LPs of a class of translates.

    Attributes
    ----------
    build, violation : callables
        The formulation's dense builder and float64 checker.
    exact_batch : callable, optional
        ``exact_batch(problems, candidates) -> list of Fraction``; without it every proof is
        made one by one.
    build_many, violations : callables, optional
        ``build`` and ``violation`` for many problems at once (``build_many(problems) -> list``,
        ``violations(problems, evidence) -> ndarray``), with the same results.
    exact_translated : callable, optional
        ``exact_translated(canon, tube, problems, shifts, groups) -> list of Fraction or None``:
        the exact checks of the translated tube for the members whose data are the canonical
        problem's moved exactly, from one check of the canonical problem
        (:func:`~tubejax.lp.evidence.check_batch.translated_tube_violations`); ``None`` entries,
        and every member without it, are checked by ``exact_batch``.
    """

    build: Callable
    violation: Callable
    exact_batch: Callable | None = None
    build_many: Callable | None = None
    violations: Callable | None = None
    exact_translated: Callable | None = None


#: The tube LP's :class:`TranslateChecks`: every batched check it has.
TUBE_CHECKS = TranslateChecks(build_tube_lp, tube_violation, exact_tube_violations, build_tube_lps, tube_violations,
                              translated_tube_violations)


def confirm_translates_with_highs(problems: Sequence, checks: TranslateChecks, provenance: str,
                                  translated: bool = True, _start_of_class=None) -> list:
    """:func:`~tubejax.lp.evidence.verdict.confirm_with_highs` of each of ``problems``, done
    together (see the module doc).

    Parameters
    ----------
    problems : sequence of TubeProblem, length K
        Meant for exact translates of one problem; any problems are answered correctly
        (another matrix is solved cold, a failed candidate is proved one by one).
    checks : TranslateChecks
        How the LPs are built and their evidence checked (:data:`TUBE_CHECKS` for the tube LP).
    provenance : str
    translated : bool
        Prove edges by exact translation where that holds (module doc).
    _start_of_class : tuple, optional
        The class's canonical problem already solved (internal: the members left after the
        translated proofs).

    Returns
    -------
    list of Verdict, length K, in order
    """
    build, violation, exact_batch, build_many, violations, exact_translated = checks
    K = len(problems)
    start = _start_of_class
    if translated and exact_batch is not None and K and start is None:
        start = _start(problems, [None], build)             # the canonical problem, solved once
        proved = _proved_by_translation(problems, start, checks, provenance) if start is not None else {}
        rest = [k for k in range(K) if k not in proved]
        if proved:
            others = confirm_translates_with_highs([problems[k] for k in rest], checks, provenance, False,
                                                   _start_of_class=start) if rest else []
            out = [proved.get(k) for k in range(K)]
            for k, v in zip(rest, others):
                out[k] = v
            return out
    lps = build_many(problems) if build_many is not None else [build(p) for p in problems]
    if start is None:
        start = _start(problems, lps, build) if K else None
    results = _solve_all(problems, lps, start)
    mins = [float(getattr(p, "min_margin", 0.0)) for p in problems]
    ok = [r.status == "Optimal" and r.margin >= m - (EXACT_BAND if m == 0 else 0.0) for r, m in zip(results, mins)]
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
        checks = _checked(exact_batch, problems, ks, cands)
        snapped = {k: (checks[k], f) for k, f in zip(ks, fv) if k in checks}
    out: list = [None] * K
    own = [k for k in range(K) if start is not None and results[k] is start[0]]   # the canonical LP itself
    for k in own:                       # their verdicts are the canonical problem's (the same inputs)
        out[k] = verdict_of_result(problems[k], lps[k], results[k], violation, provenance, snapped.get(k),
                                   viol=viols.get(k))
    tight = [k for k in range(K) if ok[k] and k not in own and not results[k].margin > TIGHT_MARGIN]
    firsts: dict = {}
    canon_v = None
    if tight and start is not None and start[0].status == "Optimal" and abs(start[0].margin) <= TIGHT_MARGIN:
        canon_v = out[own[0]] if own else verdict_of_result(start[1], start[3], start[0], violation, provenance)
    ref = canon_v                                           # the canonical problem's verdict
    if tight and exact_batch is not None and ref is not None and ref.status == "edge" \
            and ref.proof is not None and ref.proof.level == "exact":
        tube = ref.proof.exact if formulation("tube").is_exact(ref.proof.exact) else ref.tube
        cands = _translated_many(tube, np.array([_shift(problems[k]) for k in tight]))
        checks = _checked(exact_batch, problems, tight, cands)
        fv = violations([problems[k] for k in tight], [c.to_float() for c in cands]) \
            if violations is not None else [None] * len(tight)
        firsts = {k: (c, checks[k], _TRANSLATED, f) for k, c, f in zip(tight, cands, fv) if k in checks}
    for k in range(K):
        if out[k] is None:
            out[k] = verdict_of_result(problems[k], lps[k], results[k], violation, provenance, snapped.get(k),
                                       first=firsts.get(k), viol=viols.get(k))
    return out


def highs_translate_verdicts(problems: Sequence, provenance: str = "highs", translated: bool = True) -> list:
    """:func:`~tubejax.lp.evidence.verdict.highs_verdict` of each of ``problems`` (exact translates
    of one tube problem), done together (:func:`confirm_translates_with_highs`; ``translated``:
    edges proved by exact translation where that holds)."""
    return confirm_translates_with_highs(problems, TUBE_CHECKS, provenance, translated)
