"""Patrolling: the cheapest cycle that visits regions in order, reached from the start.

``plan_patrol(ts, start, ['3', '5', '6'], cycles=4)`` finds, over every *anchor*
cell ``a`` labelled ``3`` reachable from ``start``, the cheapest closed walk
``a -> (a cell labelled 5) -> (a cell labelled 6) -> a`` with at least one edge
(a layered Dijkstra, :func:`scipy.sparse.csgraph.dijkstra`, as in
:mod:`tubejax.analyses.control.planner`), then takes the anchor with the cheapest cycle
(ties: the cheapest prefix ``start -> a``, then the lowest cell id). The plan is
the prefix followed by the cycle ``cycles`` times. Every visit is witnessed by a
cell of the plan (the state is in ``Q_L``, inside that cell, at that time).

``avoid`` labels: edges whose tube may meet the closed region of an avoided label
at any step (the exact test of :mod:`tubejax.analyses.spec.labelling`, against the
region's pieces: its cells, or a box grid's label box) are not used, and the
start cell must not meet an avoided region (a start state on its boundary, or in
the part of the cell a label box cuts, would be in it). The automaton monitored
in simulation is the visiting sequence of the whole plan (:func:`~tubejax.analyses.spec.dfa.sequence_dfa`);
entries into avoided regions are counted separately.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from ..control.planner import Plan, PlanningError
from .dfa import sequence_dfa
from .formula import proposition_of
from .labelling import cell_letters, edge_letters
from .product import SpecPlan

__all__ = ["plan_patrol"]


def _allowed_edges(ts, avoid) -> np.ndarray:
    """``(E,)`` bool: edges whose tubes never meet an avoided region."""
    if not avoid:
        return np.ones(ts.n_edges, bool)
    lt = edge_letters(ts, list(avoid))
    return ~(lt.may != 0).any(axis=1)


def _cheapest(ts, allowed) -> dict:
    best = {}
    for k, e in enumerate(ts.edges):
        if allowed[k] and ((e.src, e.dst) not in best or e.L < best[e.src, e.dst][0]):
            best[e.src, e.dst] = (int(e.L), k)
    return best


def _cycle(N, best, anchor, targets):
    """Cheapest walk from ``anchor`` (at least one edge) through ``targets`` (cell sets) in order.

    Returns ``(cost, cells, edges, ends)`` or ``None``; ``ends`` index ``cells``.
    """
    K = len(targets)
    pairs = np.array(sorted(best), dtype=np.int64).reshape(-1, 2)
    w = np.array([best[tuple(p)][0] for p in pairs], float)
    V = (K + 1) * N                                      # the anchor before it leaves (no layer arcs)
    rows, cols, ws = [], [], []
    for layer in range(K + 1):
        rows.append(layer * N + pairs[:, 0]); cols.append(layer * N + pairs[:, 1]); ws.append(w)
        if layer < K:
            hit = np.array(sorted(targets[layer]), dtype=np.int64)
            rows.append(layer * N + hit); cols.append((layer + 1) * N + hit); ws.append(np.zeros(len(hit)))
    out = pairs[:, 0] == anchor
    rows.append(np.full(out.sum(), V)); cols.append(pairs[out, 1]); ws.append(w[out])
    G = sp.csr_matrix((np.concatenate(ws), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(V + 1, V + 1))
    dist, pred = dijkstra(G, directed=True, indices=V, return_predecessors=True)
    goal = K * N + anchor
    if not np.isfinite(dist[goal]):
        return None
    nodes = [goal]
    while nodes[-1] != V:
        nodes.append(int(pred[nodes[-1]]))
    nodes.reverse()
    cells, edges, ends = [anchor], [], []
    for u, v in zip(nodes[:-1], nodes[1:]):
        if u != V and v == u + N:
            ends.append(len(cells) - 1)
        else:
            cells.append(v % N)
            edges.append(best[cells[-2], cells[-1]][1])
    return float(dist[goal]), cells, edges, ends


def _path(N, best, start, goal):
    """Cheapest cell path ``start -> goal`` as ``(cells, edges)``."""
    if start == goal:
        return [start], []
    pairs = np.array(sorted(best), dtype=np.int64).reshape(-1, 2)
    w = np.array([best[tuple(p)][0] for p in pairs], float)
    G = sp.csr_matrix((w, (pairs[:, 0], pairs[:, 1])), shape=(N, N))
    _, pred = dijkstra(G, directed=True, indices=start, return_predecessors=True)
    cells = [goal]
    while cells[-1] != start:
        cells.append(int(pred[cells[-1]]))
    cells.reverse()
    return cells, [best[a, b][1] for a, b in zip(cells[:-1], cells[1:])]


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
    if not 0 <= start < N:
        raise PlanningError(f"start cell {start_cell} is not a cell id (0..{N - 1})")
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
    best = _cheapest(ts, _allowed_edges(ts, avoid))
    cells_of = {l: set(d.cells_with_label(l)) for l in labels}
    pairs = np.array(sorted(best), dtype=np.int64).reshape(-1, 2)
    G = sp.csr_matrix((np.array([best[tuple(p)][0] for p in pairs], float),
                       (pairs[:, 0], pairs[:, 1])), shape=(N, N))
    pre = dijkstra(G, directed=True, indices=start)
    anchors = sorted(a for a in cells_of[labels[0]] if np.isfinite(pre[a]))
    note = f" (edges whose tubes may meet regions {', '.join(avoid)} are not used)" if avoid else ""
    if not anchors:
        raise PlanningError(f"patrol: no cell labelled {labels[0]} is reachable from cell {start}{note}")
    targets = [cells_of[l] for l in labels[1:]]
    found = []
    for a in anchors:
        c = _cycle(N, best, a, targets + [{a}])
        if c is not None:
            found.append((c[0], float(pre[a]), a, c))
    if not found:
        raise PlanningError(f"patrol: from no cell labelled {labels[0]} reachable from cell {start} "
                            f"(cells {anchors}) is there a cycle through {' -> '.join(labels)} "
                            f"and back{note}")
    cost, pcost, a, (_, ccells, cedges, cends) = min(found, key=lambda t: t[:3])
    pcells, pedges = _path(N, best, start, a)
    cells, edges, ends = list(pcells), list(pedges), [len(pcells) - 1]
    for _ in range(int(cycles)):
        off = len(cells) - 1
        cells += ccells[1:]
        edges += cedges
        ends += [off + e for e in cends]
    seq = [labels[0]] + (labels[1:] + [labels[0]]) * int(cycles)
    targets_all = [sorted(d.cells_with_label(l)) for l in seq]
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
