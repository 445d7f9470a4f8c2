"""Planning for LTL formulas over infinite runs and patrols, and what to say when no lasso exists
(docs/math/control.md#ltl-over-infinite-runs).

:func:`plan_ltl` plans the cheapest accepting lasso (:mod:`.lasso`) of Spot's Büchi automaton; the
plan is the prefix, then ``cycles`` turns of the cycle (``SpecPlan.lasso`` keeps them apart).
:func:`explain_no_lasso` names the part that fails. A patrol (:func:`plan_patrol`) is
:func:`patrol_formula`'s lasso anchored in the first region; edges whose tubes may meet an avoided
region are never used.
"""

from __future__ import annotations

import re
import time

import numpy as np
import spot
from scipy.sparse.csgraph import dijkstra

from ..control.planner import Plan, PlanningError, _check_cell, cells_text
from .automata import Buchi, buchi_from_formula
from .dfa import sequence_dfa
from .formula import _short, proposition_of
from .labelling import cell_letters, edge_letters
from .lasso import build_buchi_product, cheapest_lasso, initial_states
from .ltl import ParsedLTL, parse_ltl
from .product import SpecPlan

__all__ = ["plan_ltl", "plan_lasso", "explain_no_lasso", "avoided_by", "patrol_formula", "plan_patrol"]


def avoided_by(parsed: ParsedLTL) -> tuple:
    """Labels ``c`` of top-level conjuncts ``G !lc`` (or ``G(!lc & !ld)``): regions never to be entered."""
    out = set()
    for c in parsed.conjuncts():
        if c.kind() != spot.op_G:
            continue
        g = c[0]
        for lit in (list(g) if g.kind() == spot.op_And else [g]):
            if lit.kind() == spot.op_Not and lit[0].kind() == spot.op_ap:
                out.add(str(lit[0]))
    return tuple(parsed.labels[parsed.propositions.index(p)] for p in sorted(out))


def patrol_formula(labels, avoid=()) -> str:
    """The LTL formula of a patrol: visit ``labels`` in this order again and again, never entering ``avoid``.

    ``['3', '5', '6']`` -> ``'G F(l3 & F(l5 & F(l6))) & G !l4'`` with ``avoid=['4']``.
    """
    seq = [f"l{l}" for l in labels]
    inner = seq[-1]
    for p in reversed(seq[:-1]):
        inner = f"{p} & F({inner})"
    out = f"G F({inner})"
    return out + "".join(f" & G !l{a}" for a in avoid)


def plan_lasso(ts, start: int, buchi: Buchi, letters=None, anchors=None):
    """The cheapest accepting lasso of the product from ``start``, its cycle through ``anchors`` if given
    (:func:`~.lasso.cheapest_lasso`); ``(lasso, product, start nodes)``."""
    if letters is None:
        letters = edge_letters(ts, buchi.labels)
    prod = build_buchi_product(ts, buchi, letters)
    q0 = initial_states(ts, buchi, start)
    starts = [q * ts.n_cells + start for q in range(buchi.n_states) if q0 >> q & 1]
    return cheapest_lasso(prod, starts, anchors), prod, starts


def _check_cycles(cycles, who: str) -> None:
    if isinstance(cycles, bool) or not isinstance(cycles, (int, np.integer)) or cycles < 1:
        raise PlanningError(f"{who}cycles must be an integer >= 1, got {cycles!r}")


def plan_ltl(ts, start_cell: int, formula: str, cycles: int = 1, key: str = "spec.ltl") -> SpecPlan:
    """Plan for an LTL formula over infinite runs: the cheapest accepting lasso (:mod:`.lasso`).

    Parameters
    ----------
    ts : TransitionSystem
        Built with method ``'tube'``.
    start_cell : int
        Where every run starts (anywhere in this closed cell).
    formula : str
        E.g. ``"GF l3 & GF l6 & G !l4"`` (:mod:`.ltl`).
    cycles : int
        Turns of the cycle in ``plan`` (the plan itself is the lasso, repeated forever).
    key : str
        The input's name in messages.

    Returns
    -------
    SpecPlan
        ``kind='ltl'``; ``dfa`` is the :class:`~.automata.Buchi` automaton, ``states`` its
        state at each cell of ``plan.cells``, ``lasso`` ``{'prefix': cells, 'cycle': cells,
        'prefix_steps', 'cycle_steps'}`` (the cycle's cells from its first to its last, which
        is the first again); ``stats`` the sizes and seconds.

    Raises
    ------
    SpecificationError
        Syntax, unknown labels, LTLf-only words, automata beyond the limits.
    PlanningError
        No lasso; the message says which part cannot be met and why.
    """
    t0 = time.perf_counter()
    start = _check_cell(ts, start_cell)
    _check_cycles(cycles, "")
    parsed = parse_ltl(formula, ts.decomposition.labels, key)
    buchi = buchi_from_formula(formula, parsed.formula, parsed.propositions, parsed.labels)
    t1 = time.perf_counter()
    letters = edge_letters(ts, buchi.labels)
    lasso, prod, _ = plan_lasso(ts, start, buchi, letters)
    if lasso is None:
        raise PlanningError(f"no plan satisfies {formula!r}: {explain_no_lasso(ts, start, parsed)}")
    N = ts.n_cells
    pcells, ccells, cells, edges = lasso.unrolled(N, cycles)
    states = [v // N for v in lasso.prefix_nodes] + [v // N for v in lasso.cycle_nodes[1:]] * int(cycles)
    steps = [int(ts.edges[k].L) for k in edges]
    ends = [len(pcells) - 1 + k * (len(ccells) - 1) for k in range(1, int(cycles) + 1)]
    lab = ts.decomposition.labels
    plan = Plan(cells, edges, steps, [f"cycle {k}" for k in range(1, int(cycles) + 1)], ends,
                [[ccells[0]]] * int(cycles), None if lab[start] is None else str(lab[start]), "lasso")
    stats = {"buchi_states": buchi.n_states, "buchi_deterministic": buchi.deterministic,
             "product_nodes": int(N * buchi.n_states), "product_arcs": int(prod.graph.nnz),
             "accepting_arcs": int(len(prod.acc_rows)), "refused_edge_states": prod.refused,
             "prefix_steps": lasso.prefix_steps, "cycle_steps": lasso.cycle_steps, "cycles": int(cycles),
             "plan_steps": plan.cost, "automaton_seconds": t1 - t0, "seconds": time.perf_counter() - t0}
    info = {"prefix": pcells, "cycle": ccells, "prefix_steps": lasso.prefix_steps,
            "cycle_steps": lasso.cycle_steps, "prefix_edges": list(lasso.prefix_edges),
            "cycle_edges": list(lasso.cycle_edges)}
    return SpecPlan(plan, buchi, tuple(states), formula, "ltl", avoided_by(parsed), stats, info)


# ----------------------------------------------------------------------------- explanations

def _region(parsed: ParsedLTL, p) -> str:
    return f"region {parsed.labels[parsed.propositions.index(str(p))]}"


def _shape(parsed: ParsedLTL, f) -> str | None:
    """``'F a'``, ``'GF a'`` or ``'FG a'`` of a single proposition, with its region; ``None`` otherwise."""
    k = f.kind()
    if k == spot.op_F and f[0].kind() == spot.op_ap:
        return "F", _region(parsed, f[0])
    if k == spot.op_G and f[0].kind() == spot.op_F and f[0][0].kind() == spot.op_ap:
        return "GF", _region(parsed, f[0][0])
    if k == spot.op_F and f[0].kind() == spot.op_G and f[0][0].kind() == spot.op_ap:
        return "FG", _region(parsed, f[0][0])
    return None


def _sub(parsed: ParsedLTL, parts) -> ParsedLTL:
    f = spot.formula.And(list(parts))
    props = tuple(sorted({str(a) for a in spot.atomic_prop_collect(f)}))
    labels = tuple(parsed.labels[parsed.propositions.index(p)] for p in props)
    return ParsedLTL(str(f), props, labels, f)


def part_ap(part: str):
    """The proposition of ``F a``, ``G F a`` or ``F G a`` (written with spaces)."""
    return spot.formula(part.split()[-1])


def _has_lasso(ts, start, parsed: ParsedLTL) -> bool:
    b = buchi_from_formula(parsed.text, parsed.formula, parsed.propositions, parsed.labels)
    return plan_lasso(ts, start, b, edge_letters(ts, b.labels))[0] is not None


def _show(f) -> str:
    """A Spot formula written with spaces between operators (``G F l3``, not ``GFl3``)."""
    return re.sub(r"(?<=[XFG])(?=[XFGl(!])", " ", str(f))


def _why(ts, parsed: ParsedLTL, part, start: int, safety=()) -> str:
    s = _shape(parsed, part)
    kept = " & ".join(f"'{_show(x)}'" for x in safety)
    with_ = f" with {kept} kept" if kept else ""
    if s is None:
        return f"'{_show(part)}' cannot be met{with_} from cell {start}"
    op, reg = s
    part = _show(part)
    if safety:
        reach = _sub(parsed, [spot.formula.F(part_ap(part))] + list(safety))
        if not _has_lasso(ts, start, reach):
            avoid = ", ".join(avoided_by(_sub(parsed, list(safety)))) or "the avoided regions"
            return (f"'{part}' cannot be met{with_}: every path from cell {start} to {reg} crosses "
                    f"region(s) {avoid}")
    if op == "F":
        return f"{reg} cannot be reached from cell {start}{with_}"
    if op == "GF":
        return (f"'{part}' asks the state to visit {reg} again and again, but no cycle of transitions "
                f"reachable from cell {start} passes through {reg}{with_}")
    return (f"'{part}' asks the state to stay in {reg} from some time on, but {reg} has no "
            f"self-sustaining cycle: no cycle of transitions reachable from cell {start} stays in it{with_}")


def explain_no_lasso(ts, start: int, parsed: ParsedLTL) -> str:
    """Why no accepting lasso exists from ``start`` (module docstring), in words."""
    f = parsed.formula
    if spot.translate(f).is_empty():
        return f"no infinite run satisfies {_short(parsed.text)!r} at all (Spot finds its automaton empty)"
    parts = parsed.conjuncts()
    b = buchi_from_formula(parsed.text, f, parsed.propositions, parsed.labels)
    if initial_states(ts, b, start) == 0:
        return (f"the start cell {start} already violates it (label {ts.decomposition.labels[start]}, "
                "or a region the cell touches)")
    safety = [c for c in parts if c.kind() == spot.op_G and c.is_syntactic_safety()]
    others = [c for c in parts if c not in safety]
    for c in others:                                       # a part alone
        if not _has_lasso(ts, start, _sub(parsed, [c])):
            return _why(ts, parsed, c, start)
    if safety:
        for c in others:
            if not _has_lasso(ts, start, _sub(parsed, [c] + safety)):
                return _why(ts, parsed, c, start, safety)
        if not others:
            kept = " & ".join(f"'{_show(x)}'" for x in safety)
            return (f"{kept} cannot be kept forever from cell {start}: every cycle reachable from it "
                    "leaves the allowed regions")
    return ("each part can be met on its own but not all together: " +
            " & ".join(f"'{_show(c)}'" for c in parts) + f" from cell {start}")


# ----------------------------------------------------------------------------- patrols

def plan_patrol(ts, start_cell: int, labels, cycles: int = 1, avoid=()) -> SpecPlan:
    """Patrol ``labels`` in order, ``cycles`` times, from ``start_cell`` (module docstring).

    Parameters
    ----------
    ts : TransitionSystem
    start_cell : int
    labels : sequence
        Regions to visit in order, ``m >= 1``; the cycle starts and ends in a cell of ``labels[0]``.
    cycles : int
        How many times the cycle is repeated in the plan, ``>= 1``.
    avoid : sequence
        Labels of regions no tube may meet.

    Returns
    -------
    SpecPlan
        ``kind='patrol'``; ``stats`` holds ``prefix_steps``, ``cycle_steps``, ``anchor``.

    Raises
    ------
    PlanningError
        Unknown labels, an avoided start cell, no reachable anchor, no cycle.
    """
    labels = [str(l) for l in labels]
    avoid = tuple(sorted({str(a) for a in avoid}))
    d, N = ts.decomposition, ts.n_cells
    start = _check_cell(ts, start_cell)
    _check_patrol(d, start, labels, cycles, avoid)
    note = f" (edges whose tubes may meet regions {', '.join(avoid)} are not used)" if avoid else ""
    lasso = _patrol_lasso(ts, start, labels, avoid, note)
    pcells, ccells, cells, edges = lasso.unrolled(N, cycles)
    a, cost, pcost = ccells[0], lasso.cycle_steps, lasso.prefix_steps
    seq = [labels[0]] + (labels[1:] + [labels[0]]) * int(cycles)
    targets_all = [sorted(d.cells_with_label(l)) for l in seq]
    ends, i = [], 0
    for l in seq:                              # the cell where each visit of the order is witnessed
        while i < len(cells) - 1 and str(d.labels[cells[i]]) != l:
            i += 1
        ends.append(i)
    ends[-1] = len(cells) - 1
    steps = [int(ts.edges[k].L) for k in edges]
    plan = Plan(cells, edges, steps, seq, ends, targets_all,
                None if d.labels[start] is None else str(d.labels[start]), "patrol")
    dfa = sequence_dfa(seq)
    states = dfa.cell_states(d.labels, cells)
    spec = f"patrol {' -> '.join(labels)} x{int(cycles)}" + (f", avoid {', '.join(avoid)}" if avoid else "")
    stats = {"anchor": int(a), "prefix_steps": int(pcost), "cycle_steps": int(cost),
             "cycles": int(cycles), "plan_steps": plan.cost}
    return SpecPlan(plan, dfa, states, spec, "patrol", avoid, stats)


def _check_patrol(d, start: int, labels: list, cycles, avoid: tuple) -> None:
    """Refuse a patrol that cannot be planned on decomposition ``d`` (:func:`plan_patrol`'s Raises)."""
    if not labels:
        raise PlanningError("patrol: give at least one region label")
    _check_cycles(cycles, "patrol: ")
    have = {str(l) for l in d.labels if l is not None}
    for l in labels + list(avoid):
        if l not in have:
            raise PlanningError(f"patrol: no cell carries label {l!r} (labels present: {sorted(have)})")
    if clash := sorted(set(labels) & set(avoid)):
        raise PlanningError(f"patrol: labels {clash} are both patrolled and avoided")
    if d.labels[start] is not None and str(d.labels[start]) in avoid:
        raise PlanningError(f"patrol: the start cell {start} lies in the avoided region {d.labels[start]}")
    if avoid and (met := cell_letters(d, list(avoid), start)[1]):
        names = ", ".join(a for b, a in enumerate(avoid) if met >> b & 1)
        raise PlanningError(f"patrol: the start cell {start} meets the avoided region {names} (a start "
                            "state on the shared boundary, or in the part of the cell the region covers, "
                            "would be in it); start in a cell away from it")
    if bad := [l for l in labels + list(avoid) if proposition_of(l) is None]:
        raise PlanningError(f"patrol: labels {bad} cannot be named in a formula (a patrol is planned as one; "
                            "labels of the characters 0-9A-Za-z can)")


def _patrol_lasso(ts, start: int, labels: list, avoid: tuple, note: str):
    """The cheapest lasso of the patrol's Büchi product from ``start`` (:func:`~.lasso.cheapest_lasso`),
    its cycle through a cell of ``labels[0]``; none is a :class:`PlanningError`."""
    d, N = ts.decomposition, ts.n_cells
    formula = patrol_formula(labels, avoid)
    parsed = parse_ltl(formula, d.labels, "spec.patrol")
    buchi = buchi_from_formula(formula, parsed.formula, parsed.propositions, parsed.labels)
    anchors = np.zeros((buchi.n_states, N), bool)
    anchors[:, sorted(d.cells_with_label(labels[0]))] = True
    lasso, prod, starts = plan_lasso(ts, start, buchi, anchors=anchors.ravel())
    if lasso is not None:
        return lasso
    d0 = dijkstra(prod.graph, directed=True, indices=starts, min_only=True) if starts else np.full(anchors.size, np.inf)
    if not (reach := np.flatnonzero(anchors.ravel() & np.isfinite(d0))).size:
        raise PlanningError(f"patrol: no cell labelled {labels[0]} is reachable from cell {start}{note}")
    raise PlanningError(f"patrol: from no cell labelled {labels[0]} reachable from cell {start} "
                        f"(cells {cells_text(sorted({int(v % N) for v in reach}))}) is there a cycle through "
                        f"{' -> '.join(labels)} and back{note}")
