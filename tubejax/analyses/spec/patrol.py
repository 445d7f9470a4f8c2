"""Patrolling: the cheapest cycle that visits regions in order, reached from the start.

A patrol is one case of LTL over infinite runs: ``plan_patrol(ts, start, ['3', '5', '6'],
cycles=4, avoid=['4'])`` plans the formula ``G F(l3 & F(l5 & F(l6))) & G !l4``
(:func:`~tubejax.analyses.spec.ltl_plans.patrol_formula`) through the sound product with its
Büchi automaton (:mod:`tubejax.analyses.spec.lasso`), with the cycle anchored in the first
region: over every *anchor* cell ``a`` labelled ``3`` reachable from ``start``, the cheapest
accepting cycle through ``a`` (ties: the cheapest prefix ``start -> a``, then the lowest
node). The plan is the prefix followed by the cycle ``cycles`` times; visits are read from
every time step of the tubes, as for formulas.

``avoid`` labels: an edge whose tube may meet the closed region of an avoided label
at any step (the exact test of :mod:`tubejax.analyses.spec.labelling`, against the
region's pieces: its cells, or a box grid's label box) leads the automaton to its
rejecting sink, so it is never used, and the
start cell must not meet an avoided region (a start state on its boundary, or in
the part of the cell a label box cuts, would be in it). The automaton monitored
in simulation is the visiting sequence of the whole plan (:func:`~tubejax.analyses.spec.dfa.sequence_dfa`);
entries into avoided regions are counted separately.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import dijkstra

from ..control.planner import Plan, PlanningError
from .automata import buchi_from_formula
from .dfa import sequence_dfa
from .formula import proposition_of
from .labelling import cell_letters, edge_letters
from .lasso import build_buchi_product, cheapest_lasso, initial_states
from .ltl import parse_ltl
from .ltl_plans import patrol_formula
from .product import SpecPlan

__all__ = ["plan_patrol"]


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
    d = ts.decomposition
    N = ts.n_cells
    start = int(start_cell)
    _check_patrol(d, start, labels, cycles, avoid)
    note = f" (edges whose tubes may meet regions {', '.join(avoid)} are not used)" if avoid else ""
    lasso = _patrol_lasso(ts, start, labels, avoid, note)
    pcells = [int(v % N) for v in lasso.prefix_nodes]
    ccells = [int(v % N) for v in lasso.cycle_nodes]
    cells = pcells + ccells[1:] * int(cycles)
    edges = list(lasso.prefix_edges) + list(lasso.cycle_edges) * int(cycles)
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
    dfa = sequence_dfa(seq, [proposition_of(l) or l for l in sorted(set(seq))])
    lab_mask = [dfa.letter([] if d.labels[c] is None else [d.labels[c]]) for c in cells]
    states = tuple(int(s) for s in dfa.run(np.array(lab_mask)))
    spec = f"patrol {' -> '.join(labels)} x{int(cycles)}" + (f", avoid {', '.join(avoid)}" if avoid else "")
    stats = {"anchor": int(a), "prefix_steps": int(pcost), "cycle_steps": int(cost),
             "cycles": int(cycles), "plan_steps": plan.cost}
    return SpecPlan(plan, dfa, states, spec, "patrol", avoid, stats)


def _check_patrol(d, start: int, labels: list, cycles, avoid: tuple) -> None:
    """Refuse a patrol that cannot be planned on decomposition ``d`` (:func:`plan_patrol`'s Raises)."""
    N = d.n_cells
    if not 0 <= start < N:
        raise PlanningError(f"start cell {start} is not a cell id (0..{N - 1})")
    if not labels:
        raise PlanningError("patrol: give at least one region label")
    if isinstance(cycles, bool) or not isinstance(cycles, (int, np.integer)) or cycles < 1:
        raise PlanningError(f"patrol: cycles must be an integer >= 1, got {cycles!r}")
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
    prod = build_buchi_product(ts, buchi, edge_letters(ts, buchi.labels))
    q0 = initial_states(ts, buchi, start)
    starts = [q * N + start for q in range(buchi.n_states) if q0 >> q & 1]
    anchor_cells = sorted(d.cells_with_label(labels[0]))
    anchors = np.zeros(N * buchi.n_states, bool)
    for q in range(buchi.n_states):
        anchors[q * N + np.array(anchor_cells, dtype=np.int64)] = True
    d0 = dijkstra(prod.graph, directed=True, indices=starts, min_only=True) if starts else np.full(len(anchors), np.inf)
    if not (anchors & np.isfinite(d0)).any():
        raise PlanningError(f"patrol: no cell labelled {labels[0]} is reachable from cell {start}{note}")
    lasso = cheapest_lasso(prod, starts, anchors)
    if lasso is None:
        reach = sorted({int(v % N) for v in np.flatnonzero(anchors & np.isfinite(d0))})
        raise PlanningError(f"patrol: from no cell labelled {labels[0]} reachable from cell {start} "
                            f"(cells {reach}) is there a cycle through {' -> '.join(labels)} "
                            f"and back{note}")
    return lasso
