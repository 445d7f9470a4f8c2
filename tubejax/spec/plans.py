"""Planners for the three kinds of specification, and what to say when one cannot be met.

:func:`plan_formula` (an LTLf formula), :func:`plan_sequence_spec` (a visiting
sequence through the product) and :func:`sequence_spec_plan` (a cell-level
:func:`tubejax.control.plan_sequence` plan with its automaton, for monitoring).
Patrols are in :mod:`tubejax.spec.patrol`.

When no plan satisfies a formula, the top-level conjuncts are tried alone, then
in pairs; the message names the first part that cannot be met on its own, or
the first pair that cannot be met together, and which regions cannot be reached
while the other part is kept (e.g. "every path to region 6 crosses region 4").
"""

from __future__ import annotations

import numpy as np

from ..control.planner import Plan, PlanningError
from .dfa import DFA, dfa_from_formula, sequence_dfa
from .formula import ParsedFormula, parse_formula, proposition_of
from .labelling import edge_letters, map_alphabet
from .product import NoPlanError, SpecPlan, _check_start, _reached, build_product, plan_dfa

__all__ = ["plan_formula", "plan_sequence_spec", "sequence_spec_plan"]


def plan_formula(ts, start_cell: int, formula: str) -> SpecPlan:
    """Plan for an LTLf formula over region labels (:mod:`tubejax.spec.formula`).

    Parameters
    ----------
    ts : TransitionSystem
        Built with method ``'tube'``.
    start_cell : int
        Where every run starts (anywhere in this closed cell).
    formula : str
        E.g. ``"F(l3 & F(l5 & F l6)) & G(!l4)"``.

    Returns
    -------
    SpecPlan
        ``kind='formula'``; the DFA is built over the letters the map can produce
        (:func:`~tubejax.spec.labelling.map_alphabet`).

    Raises
    ------
    SpecificationError
        Syntax errors, unknown propositions (with their positions).
    PlanningError
        No plan satisfies the formula; the message says which part cannot be met,
        e.g. ``"'F(l6)' cannot be met together with 'G(!(l4))': with 'G(!(l4))' kept,
        region 6 cannot be reached from cell 0"``.
    """
    start = _check_start(ts, start_cell)
    parsed = parse_formula(formula, ts.decomposition.labels)
    dfa = dfa_from_formula(parsed, map_alphabet(ts.decomposition, parsed.labels))
    letters = edge_letters(ts, dfa.labels)
    try:
        return plan_dfa(ts, start, dfa, "formula", letters)
    except NoPlanError as err:
        raise PlanningError(f"no plan satisfies {formula!r}: "
                            f"{_explain(ts, start, parsed, letters, dfa.alphabet, err)}") from None
    except PlanningError as err:
        raise PlanningError(f"no plan satisfies {formula!r}: {err}") from None


def _sub_dfa(parsed: ParsedFormula, parts, alphabet) -> DFA:
    from flloat.ltlf import LTLfAnd
    f = parts[0] if len(parts) == 1 else LTLfAnd(list(parts))
    text = " & ".join(parsed.render(p) for p in parts)
    return dfa_from_formula(ParsedFormula(text, parsed.propositions, parsed.labels, f), alphabet)


def _explain(ts, start, parsed: ParsedFormula, letters, alphabet, err) -> str:
    """Which part of the formula cannot be met (top-level conjuncts, then pairs of them)."""
    parts = parsed.conjuncts()
    if len(parts) < 2:
        return str(err)

    def ok(ps):
        try:
            plan_dfa(ts, start, _sub_dfa(parsed, ps, alphabet), letters=letters)
            return True
        except PlanningError:
            return False

    for p in parts:
        if not ok([p]):
            return f"part {parsed.render(p)!r} cannot be met on its own from cell {start}"
    for a in range(len(parts)):
        for b in range(a + 1, len(parts)):
            if not ok([parts[a], parts[b]]):
                reach, keep = (a, b) if _has_eventually(parts[a]) or not _has_eventually(parts[b]) else (b, a)
                A, B = parsed.render(parts[reach]), parsed.render(parts[keep])
                why = _cause(ts, start, parsed, parts[keep], letters, alphabet, parts[reach].find_labels())
                return f"part {A!r} cannot be met together with {B!r}" + (f": {why}" if why else "")
    return "its parts can each be met, and every two of them together, but not all at once"


def _has_eventually(f) -> bool:
    return any(tok in str(f) for tok in ("F(", "U", "last"))


def _cause(ts, start, parsed, keep, letters, alphabet, want) -> str:
    """Which regions of ``want`` (internal proposition names) cannot be reached while ``keep`` can still be met."""
    dfa = _sub_dfa(parsed, [keep], alphabet)
    try:
        cells, _ = _reached(ts, dfa, start, build_product(ts, dfa, letters))
    except PlanningError:
        return ""
    lab = ts.decomposition.labels
    missing = [parsed.labels[int(p[1:])] for p in sorted(want)
               if not any(lab[c] is not None and str(lab[c]) == parsed.labels[int(p[1:])] for c in cells)]
    if not missing:
        return ""
    return (f"with {parsed.render(keep)!r} kept, region {', '.join(missing)} cannot be reached from "
            f"cell {start} (every path there enters, or has a tube that may sweep, a region it forbids)")


def plan_sequence_spec(ts, start_cell: int, labels) -> SpecPlan:
    """A label sequence as a specification: the product with :func:`~tubejax.spec.dfa.sequence_dfa`.

    Like :func:`tubejax.control.plan_sequence` (``'exact'``), but visits are read
    from every time step of the tubes: a tube set lying inside a target cell counts
    as a visit, one that may or may not meet it counts as none. Never more steps
    than ``plan_sequence``.

    Parameters
    ----------
    ts : TransitionSystem
    start_cell : int
    labels : sequence
        Targets in order (the start cell's own label is not one of them).

    Returns
    -------
    SpecPlan
        ``kind='sequence'``.

    Raises
    ------
    PlanningError
        A label carried by no cell, or a segment that cannot be completed (named).
    """
    start = _check_start(ts, start_cell)
    labels = [str(l) for l in labels]
    have = {str(l) for l in ts.decomposition.labels if l is not None}
    for k, l in enumerate(labels):
        if l not in have:
            raise PlanningError(f"segment {k + 1}: no cell carries label {l!r} "
                                f"(labels present: {sorted(have)})")
    props = [proposition_of(l) or l for l in sorted(set(labels))]
    dfa = sequence_dfa(labels, props)
    letters = edge_letters(ts, dfa.labels)
    try:
        return plan_dfa(ts, start, dfa, "sequence", letters)
    except NoPlanError:
        product = build_product(ts, dfa, letters)
        _, k = _reached(ts, dfa, start, product)
        lab = ts.decomposition.labels
        fr = (f"label {lab[start]}" if lab[start] is not None else "start") if k == 0 else f"label {labels[k - 1]}"
        raise PlanningError(f"segment {k + 1} ({fr} -> label {labels[k]}): no path from the cells "
                            f"reached after {k} targets to any cell labelled {labels[k]} whose tubes "
                            "keep the visits in order") from None


def sequence_spec_plan(ts, plan: Plan) -> SpecPlan:
    """A :func:`tubejax.control.plan_sequence` plan with the automaton of its target sequence.

    The plan is kept as it is (every visit is witnessed by a cell of the path); the
    :func:`~tubejax.spec.dfa.sequence_dfa` of ``plan.labels`` is what its runs are
    monitored against.
    """
    if not plan.labels or any(l is None for l in plan.labels):
        raise PlanningError("sequence_spec_plan needs a plan with target labels (from plan_sequence)")
    labels = [str(l) for l in plan.labels]
    dfa = sequence_dfa(labels, [proposition_of(l) or l for l in sorted(set(labels))])
    lab = ts.decomposition.labels
    letters = [dfa.letter([] if lab[c] is None else [lab[c]]) for c in plan.cells]
    states = tuple(int(s) for s in dfa.run(np.array(letters)))
    return SpecPlan(plan, dfa, states, " -> ".join([str(plan.start_label or "start")] + labels),
                    "sequence", (), {"plan_steps": plan.cost, "planner": plan.method})
