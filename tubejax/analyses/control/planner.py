"""High-level control (Algorithm 3, step 1): Dijkstra over the transition system, an edge costing its
horizon ``L``, for a sequence of region labels to visit in order
(docs/math/control.md#planning-over-the-transition-system). The graph is built in a fixed order, so
the same input gives the same plan; a segment whose start already carries the next label is empty.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

__all__ = ["Plan", "PlanningError", "plan_to_label", "plan_sequence", "plan_edge", "cells_text"]


class PlanningError(ValueError):
    """No plan satisfies the specification; the message names the failing segment."""


@dataclass(frozen=True)
class Plan:
    """A path through the transition system that visits target regions in order.

    Attributes
    ----------
    cells : list of int
        Cell path ``s(0), ..., s(d)``, length ``d + 1``.
    edges : list of int
        Indices into ``ts.edges`` of the ``d`` transitions used.
    steps : list of int
        Horizon ``L`` of each used edge, length ``d``.
    labels : list
        The target labels, one per segment (``None`` for a plan built from an edge).
    segment_ends : list of int
        For each segment, the index into ``cells`` where it ends (non-decreasing;
        the last one is ``d``).
    target_cells : list of list of int
        For each segment, the cells that count as reaching its target.
    start_label : object
        Label of the start cell (``None`` if unlabelled).
    """

    cells: list
    edges: list
    steps: list
    labels: list
    segment_ends: list
    target_cells: list
    start_label: object = None
    method: str = "exact"
    _meta: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def cost(self) -> int:
        """Total number of time steps ``sum L``."""
        return int(sum(self.steps))

    @property
    def times(self) -> np.ndarray:
        """Time at which the state should be in ``cells[c]``, shape ``(d + 1,)``."""
        return np.concatenate([[0], np.cumsum(np.asarray(self.steps, dtype=int))]).astype(int)

    @property
    def segment_times(self) -> list:
        """Time step at which each segment ends."""
        t = self.times
        return [int(t[c]) for c in self.segment_ends]

    @property
    def segment_costs(self) -> list:
        """Cost of each segment."""
        t = self.segment_times
        return [t[0]] + [t[k] - t[k - 1] for k in range(1, len(t))]

    def segment_cells(self, k: int) -> list:
        """Cell path of segment ``k`` (0-based), including its start cell."""
        lo = 0 if k == 0 else self.segment_ends[k - 1]
        return self.cells[lo:self.segment_ends[k] + 1]


def _graph(ts):
    """The cheapest edge per ordered pair (the first such edge on ties), from the edge arrays
    (:meth:`~tubejax.transitions.transition_system.TransitionSystem.edge_arrays`).

    Returns
    -------
    pairs : ndarray of int, shape (P, 2)     ``(src, dst)``, sorted
    cost : ndarray of int, shape (P,)        its ``L``
    edge : ndarray of int, shape (P,)        its index into ``ts.edges``
    """
    a = ts.edge_arrays()
    src, dst, L = a.src, a.dst, a.L
    if not np.any(a.key[1:] == a.key[:-1]):          # one edge per pair (as in every file): sorted by the key
        k = a.order
        return np.stack([src[k], dst[k]], axis=1), L[k], k
    order = np.lexsort((np.arange(len(src)), L, dst, src))
    first = np.ones(len(order), dtype=bool)
    first[1:] = (src[order][1:] != src[order][:-1]) | (dst[order][1:] != dst[order][:-1])
    k = order[first]
    return np.stack([src[k], dst[k]], axis=1), L[k], k


def cells_text(cells, head: int = 20, tail: int = 0, note: str = "") -> str:
    """Cell ids for a message: all of them, or the first ``head`` and the last ``tail`` around the count of
    the others (followed by ``note``), so that a message about a million cells stays a line."""
    cells = [int(c) for c in cells]
    if len(cells) <= head + tail:
        return str(cells)
    end = f" ..., {', '.join(map(str, cells[-tail:]))}" if tail else ""
    return f"[{', '.join(map(str, cells[:head]))}, ... ({len(cells) - head - tail:,} more{note}){end}]"


def _leaves(ts, cell: int) -> bool:
    """Whether some edge leaves ``cell``."""
    a = ts.edge_arrays()
    at = np.searchsorted(a.key, cell * np.int64(ts.n_cells))
    return bool(at < len(a.key) and a.key[at] < (cell + 1) * np.int64(ts.n_cells))


def _labels(ts) -> list:
    return [None if l is None else str(l) for l in ts.decomposition.labels]


def _check_cell(ts, cell) -> int:
    c = int(cell)
    if not 0 <= c < ts.n_cells:
        raise PlanningError(f"start cell {cell} is not a cell id (0..{ts.n_cells - 1})")
    return c


def _check_labels(ts, labels) -> list:
    lab = _labels(ts)
    out = []
    for k, l in enumerate(labels):
        s = str(l)
        if s not in lab:
            have = sorted({x for x in lab if x is not None})
            raise PlanningError(f"segment {k + 1}: no cell carries label {s!r} "
                                f"(labels present: {have})")
        out.append(s)
    return out


def _segment_name(k, from_label, to_label):
    fr = "start" if from_label is None else f"label {from_label}"
    return f"segment {k + 1} ({fr} -> label {to_label})"


def predecessor_path(pred, a: int, b: int) -> list:
    """Nodes from ``a`` to ``b`` along Dijkstra predecessors ``pred`` (from source ``a``)."""
    out = [b]
    while out[-1] != a:
        out.append(int(pred[out[-1]]))
    return out[::-1]


def _layered_graph(pairs, cost, hits, N: int) -> sp.csr_matrix:
    """The CSR matrix of ``K + 1 = len(hits) + 1`` copies of the graph (``pairs`` sorted, their ``cost``), node
    ``layer * N + i``, with a zero-cost arc ``(k, i) -> (k + 1, i)`` for each cell ``i`` of ``hits[k]`` (sorted,
    distinct). Filled in place, row by row in column order, as ``csr_matrix((w, (rows, cols)))`` orders it,
    without its coordinate copies (docs/explanation/performance.md#the-planners-graph)."""
    K = len(hits)
    deg = np.bincount(pairs[:, 0], minlength=N).astype(np.int64)
    counts = np.tile(deg, K + 1)
    for layer, hit in enumerate(hits):
        counts[layer * N + hit] += 1
    indptr = np.concatenate([[0], np.cumsum(counts)])
    index = np.int32 if max(int(indptr[-1]), (K + 1) * N) < 2 ** 31 else np.int64
    indices, data = np.empty(int(indptr[-1]), index), np.empty(int(indptr[-1]))
    within = np.arange(len(pairs)) - np.repeat(np.cumsum(deg) - deg, deg)    # an arc's place in its row
    for layer in range(K + 1):
        at = indptr[layer * N + pairs[:, 0]] + within
        indices[at], data[at] = layer * N + pairs[:, 1], cost
        if layer < K:                           # after the row's arcs: its column is the largest
            at = indptr[layer * N + hits[layer]] + deg[hits[layer]]
            indices[at], data[at] = (layer + 1) * N + hits[layer], 0.0   # explicit zeros are arcs in csgraph
    return sp.csr_matrix((data, indices, indptr), shape=((K + 1) * N,) * 2)


def _plan_layered(ts, start, labels):
    """Dijkstra (scipy.sparse.csgraph) over ``K + 1`` copies of the graph; layer ``k`` means
    "the first ``k`` targets are visited", and a zero-cost arc ``(k, i) -> (k + 1, i)``
    exists when cell ``i`` carries label ``k + 1``."""
    N, K = ts.n_cells, len(labels)
    (pairs, cost, edge_of), lab = _graph(ts), _labels(ts)
    cost = cost.astype(float)
    pair_key = pairs[:, 0] * N + pairs[:, 1]
    hits = [np.array([i for i in range(N) if lab[i] == labels[layer]], dtype=np.int64) for layer in range(K)]
    G = _layered_graph(pairs, cost, hits, N)
    dist, pred = dijkstra(G, directed=True, indices=start, return_predecessors=True)
    for layer in range(1, K + 1):
        d = dist[layer * N:(layer + 1) * N]
        if not np.isfinite(d).any():
            prev = dist[(layer - 1) * N:layer * N]
            reach = np.flatnonzero(np.isfinite(prev))
            fr = labels[layer - 2] if layer >= 2 else lab[start]
            src = (f"cell {start}" + ("" if _leaves(ts, start) else " (it has no outgoing transition)")
                   if layer == 1 else f"any of the cells {cells_text(reach)} reachable after segment {layer - 1}")
            raise PlanningError(f"{_segment_name(layer - 1, fr, labels[layer - 1])}: no path "
                                f"from {src} to any cell labelled {labels[layer - 1]}")
    nodes = predecessor_path(pred, start, K * N + int(np.argmin(dist[K * N:])))
    cells, edges, ends = [nodes[0] % N], [], []
    for u, v in zip(nodes[:-1], nodes[1:]):
        if v == u + N:                            # layer change: segment ends here
            ends.append(len(cells) - 1)
        else:
            cells.append(v % N)
            edges.append(int(edge_of[np.searchsorted(pair_key, (u % N) * N + v % N)]))
    return cells, edges, ends


def plan_to_label(ts, start_cell: int, label) -> list:
    """Least-cost cell path from ``start_cell`` to any cell labelled ``label``.

    Parameters
    ----------
    ts : TransitionSystem
    start_cell : int
    label : str or int
        Compared as a string with the cell labels.

    Returns
    -------
    list of int
        The cell path, starting with ``start_cell`` (just ``[start_cell]`` if
        it already carries ``label``).

    Raises
    ------
    PlanningError
        No cell carries ``label``, or none is reachable.
    """
    return plan_sequence(ts, start_cell, [label]).cells


def plan_sequence(ts, start_cell: int, labels, method: str = "exact") -> Plan:
    """Plan a path from ``start_cell`` visiting cells of ``labels`` in order.

    Parameters
    ----------
    ts : TransitionSystem
    start_cell : int
        The initial cell (e.g. a cell of region 1 for the paper's task).
    labels : sequence
        Target labels, in the order they must be visited (e.g. ``[3, 4, 5, 6]``).
    method : {'exact', 'greedy'}
        Least total cost over the whole sequence (layered Dijkstra) or the
        paper's segment-by-segment choice (see the module docstring).

    Returns
    -------
    Plan

    Raises
    ------
    PlanningError
        A label carried by no cell, or a segment with no path; the message names
        the segment, e.g. ``"segment 2 (label 3 -> label 4): no path from cell 12
        to any cell labelled 4"``.
    """
    start = _check_cell(ts, start_cell)
    labels = _check_labels(ts, list(labels))
    if len(labels) == 0:
        raise PlanningError("the specification is empty: give at least one target label")
    lab = _labels(ts)
    if method == "exact":
        cells, edges, ends = _plan_layered(ts, start, labels)
    elif method == "greedy":
        cells, edges, ends = [start], [], []
        for k, l in enumerate(labels):
            try:
                c, e, _ = _plan_layered(ts, cells[-1], [l])
            except PlanningError as err:
                fr = lab[start] if k == 0 else labels[k - 1]
                msg = str(err).split(": ", 1)[1]
                raise PlanningError(f"{_segment_name(k, fr, l)}: {msg}") from None
            cells += c[1:]
            edges += e
            ends.append(len(cells) - 1)
    else:
        raise ValueError(f"method must be 'exact' or 'greedy', got {method!r}")
    steps = [int(ts.edges[k].L) for k in edges]
    targets = [[i for i in range(ts.n_cells) if lab[i] == l] for l in labels]
    return Plan(cells, edges, steps, labels, ends, targets, lab[start], method)


def plan_edge(ts, k: int) -> Plan:
    """A one-segment :class:`Plan` following edge ``k`` (target: its destination cell)."""
    e = ts.edges[int(k)]
    return Plan([int(e.src), int(e.dst)], [int(k)], [int(e.L)], [None], [1], [[int(e.dst)]],
                _labels(ts)[e.src], "edge")
