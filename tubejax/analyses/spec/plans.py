"""Planners for LTLf formulas (:func:`plan_formula`) and visiting sequences (:func:`plan_sequence_spec`
through the product, :func:`sequence_spec_plan` for a cell-level plan with its automaton, for monitoring)."""

from __future__ import annotations

from ..control.planner import Plan, PlanningError, _check_cell, _check_labels, _segment_name
from .dfa import sequence_dfa
from .explain import explain_no_plan, explain_start, explain_unsatisfiable
from .formula import parse_formula
from .automata import dfa_from_formula
from .labelling import edge_letters, map_alphabet
from .product import NoPlanError, SpecPlan, _reached, build_product, plan_dfa

__all__ = ["plan_formula", "plan_sequence_spec", "sequence_spec_plan"]


def plan_formula(ts, start_cell: int, formula: str) -> SpecPlan:
    """Plan for an LTLf formula over region labels (:mod:`tubejax.analyses.spec.formula`).

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
        (:func:`~tubejax.analyses.spec.labelling.map_alphabet`).

    Raises
    ------
    SpecificationError
        Syntax errors, unknown propositions (with their positions), nesting or an
        automaton beyond the limits (:mod:`tubejax.analyses.spec.formula`,
        :mod:`tubejax.analyses.spec.automata`).
    PlanningError
        No plan satisfies the formula; the message says which part fails and why
        (:mod:`tubejax.analyses.spec.explain`), e.g. ``"part 'F(l6)' cannot be met together with
        'G(!(l4))': with 'G(!(l4))' kept, region 6 cannot be reached from cell 0"`` or
        ``"parts 'F(l3)' and 'G(!(l3))' contradict each other: ..."``.
    """
    start = _check_cell(ts, start_cell)
    parsed = parse_formula(formula, ts.decomposition.labels)
    alphabet = map_alphabet(ts.decomposition, parsed.labels)
    dfa = dfa_from_formula(parsed, alphabet)
    if not dfa.satisfiable():
        raise PlanningError(f"no plan satisfies {formula!r}: {explain_unsatisfiable(parsed, alphabet)}")
    letters = edge_letters(ts, dfa.labels)
    try:
        return plan_dfa(ts, start, dfa, "formula", letters)
    except NoPlanError:
        raise PlanningError(f"no plan satisfies {formula!r}: "
                            f"{explain_no_plan(ts, start, parsed, letters, dfa.alphabet)}") from None
    except PlanningError as err:                     # the start cell violates it, or may
        raise PlanningError(f"no plan satisfies {formula!r}: "
                            f"{explain_start(ts, start, parsed, dfa, err)}") from None


def plan_sequence_spec(ts, start_cell: int, labels) -> SpecPlan:
    """A label sequence as a specification: the product with :func:`~tubejax.analyses.spec.dfa.sequence_dfa`.

    Like :func:`tubejax.analyses.control.plan_sequence` (``'exact'``), but visits are read
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
    start = _check_cell(ts, start_cell)
    labels = _check_labels(ts, labels)
    dfa = sequence_dfa(labels)
    letters = edge_letters(ts, dfa.labels)
    try:
        return plan_dfa(ts, start, dfa, "sequence", letters)
    except NoPlanError:
        product = build_product(ts, dfa, letters)
        _, k = _reached(ts, dfa, start, product)
        fr = ts.decomposition.labels[start] if k == 0 else labels[k - 1]
        raise PlanningError(f"{_segment_name(k, fr, labels[k])}: no path from the cells reached after {k} "
                            f"targets to any cell labelled {labels[k]} whose tubes keep the visits in order") from None


def sequence_spec_plan(ts, plan: Plan) -> SpecPlan:
    """A :func:`tubejax.analyses.control.plan_sequence` plan with the automaton of its target sequence.

    The plan is kept as it is (every visit is witnessed by a cell of the path); the
    :func:`~tubejax.analyses.spec.dfa.sequence_dfa` of ``plan.labels`` is what its runs are
    monitored against.
    """
    if not plan.labels or any(l is None for l in plan.labels):
        raise PlanningError("sequence_spec_plan needs a plan with target labels (from plan_sequence)")
    labels = [str(l) for l in plan.labels]
    dfa = sequence_dfa(labels)
    states = dfa.cell_states(ts.decomposition.labels, plan.cells)
    return SpecPlan(plan, dfa, states, " -> ".join([str(plan.start_label or "start")] + labels),
                    "sequence", (), {"plan_steps": plan.cost, "planner": plan.method})
