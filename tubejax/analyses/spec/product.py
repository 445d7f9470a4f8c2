"""The sound product of the transition system with a DFA, and Dijkstra over it
(the rule and why it is sound: docs/math/control.md#specifications).

Node ``(cell i, DFA state q)`` is ``q * N + i``; arcs into states that cannot reach acceptance are
dropped; ``q_0`` follows the arcs' rule from the letters of ``x(0)``. Ties: lowest DFA state, then cell.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from ..control.planner import Plan, PlanningError, _check_cell, predecessor_path
from .dfa import DFA
from .formula import SpecificationError
from .labelling import EdgeLetters, cell_letters, edge_letters, map_alphabet, start_letters, submasks

__all__ = ["SpecPlan", "NoPlanError", "Product", "build_product", "edge_successors", "plan_dfa",
           "avoided_labels", "MAX_PRODUCT_PAIRS"]

#: Most (edge, DFA state) pairs a product may have: its arrays take about 40 bytes a pair,
#: so this bounds them near 1 GB; bigger products are refused before they are built.
MAX_PRODUCT_PAIRS = 25_000_000


class NoPlanError(PlanningError):
    """No accepting product node is reachable (the start itself is fine)."""


@dataclass(frozen=True, eq=False)
class SpecPlan:
    """A plan that satisfies a temporal specification.

    Attributes
    ----------
    plan : Plan
        The cell path (what :func:`tubejax.analyses.control.simulate` follows).
    dfa : DFA
        The automaton every run is monitored against.
    states : tuple of int
        DFA state at each cell of ``plan.cells`` (after the letter of that time step).
    spec : str
        The formula, sequence or patrol it was planned for.
    kind : str
        ``'formula'``, ``'sequence'``, ``'patrol'`` or ``'ltl'`` (then ``dfa`` is a Büchi automaton).
    avoid : tuple of str
        Labels of the regions the specification forbids at some point (drawn shaded).
    stats : dict
        Product size, refused arcs, seconds.
    lasso : dict, optional
        For ``kind='ltl'``: ``prefix`` and ``cycle`` (cell ids; the cycle's last cell is its
        first), their steps and edges (:func:`~tubejax.analyses.spec.ltl_plans.plan_ltl`).
    """

    plan: Plan
    dfa: DFA
    states: tuple
    spec: str
    kind: str
    avoid: tuple = ()
    stats: dict = field(default_factory=dict)
    lasso: dict | None = None

    @property
    def cost(self) -> int:
        return self.plan.cost


def edge_successors(dfa: DFA, letters: EdgeLetters, alphabet=None) -> np.ndarray:
    """``succ (E, n_states)``: the DFA state edge ``e`` is planned to lead to from ``q`` (``-1``: refused).

    ``R_e = M_1 M_2 ... M_L`` (boolean), ``M_l[q, q'] = any S in [must_l, may_l] with
    delta(q, S) = q'``; edges with the same letter sets share the work. The
    successor is the state ``m`` of ``R_e(q)`` whose language is contained in that of
    every other (``R_e(q) = {m}`` in particular); ``-1`` when there is none.
    Letters outside ``alphabet`` (``(2**k,)`` bool, e.g. :func:`map_alphabet`) cannot
    occur and are skipped.
    """
    E, nq = len(letters.L), dfa.n_states
    if E == 0:
        return np.zeros((0, nq), np.int64)
    keys, inv = letters.distinct()
    rel = {}
    ok = np.ones(dfa.n_letters, bool) if alphabet is None else np.asarray(alphabet, bool)
    notincl_T = sp.csr_matrix((~dfa.inclusion()).T.astype(np.int32))
    rows = np.arange(nq)
    succ_u = np.empty((len(keys), nq), np.int64)
    for u, key in enumerate(keys):
        R = sp.identity(nq, dtype=np.int32, format="csr")
        for must, may in key:
            if (must, may) not in rel:
                to = [dfa.delta[:, must | s] for s in submasks(may & ~must) if ok[must | s]]
                cols = np.concatenate(to) if to else np.zeros(0, np.int64)
                M = sp.csr_matrix((np.ones(len(cols), np.int32), (np.tile(rows, len(to)), cols)),
                                  shape=(nq, nq))
                M.data[:] = 1                                        # duplicates summed: back to 0/1
                rel[must, may] = M
            R = R @ rel[must, may]
            R.data[:] = 1                                            # boolean product
        bad = (R @ notincl_T).toarray() > 0          # [q, m]: some reachable r is not covered by m
        dom = (R.toarray() > 0) & ~bad
        succ_u[u] = np.where(dom.any(axis=1), dom.argmax(axis=1), -1)
    return succ_u[inv]


@dataclass(frozen=True, eq=False)
class Product:
    """The product graph (see the module docstring).

    Attributes
    ----------
    graph : scipy.sparse.csr_matrix, shape (n_states * N, n_states * N)
        Node ``q * N + i`` is ``(cell i, state q)``; weights are ``L``.
    arc_edge : dict
        ``{(u, v): edge index}`` of the cheapest edge behind each arc.
    succ : ndarray, shape (E, n_states)
        :func:`edge_successors`.
    refused : int
        Pairs (edge, live state) refused because the edge's letters disagree.
    """

    graph: sp.csr_matrix
    arc_edge: dict
    succ: np.ndarray
    refused: int
    n_cells: int
    n_states: int


def build_product(ts, dfa: DFA, letters: EdgeLetters | None = None) -> Product:
    """The product of ``ts`` (all edges) with ``dfa``; ``letters`` of all edges for ``dfa.labels`` (computed if
    not given). More than :data:`MAX_PRODUCT_PAIRS` (edge, DFA state) pairs: :class:`SpecificationError`."""
    src, dst, Ls = edge_arrays(ts, dfa.n_states, f"automaton of {dfa.description!r}", "specification")
    if letters is None:
        letters = edge_letters(ts, dfa.labels)
    succ = edge_successors(dfa, letters, map_alphabet(ts.decomposition, dfa.labels))
    N, nq, E = ts.n_cells, dfa.n_states, ts.n_edges
    live = dfa.live()
    q = np.broadcast_to(np.arange(nq), (E, nq))
    ok = (succ >= 0) & live[np.maximum(succ, 0)] & live[q]
    refused = int(((succ < 0) & live[q]).sum())
    e_idx, q_idx = np.nonzero(ok)
    rows = q_idx * N + src[e_idx]
    cols = succ[e_idx, q_idx] * N + dst[e_idx]
    rows, cols, w, e_idx = cheapest_arcs(rows, cols, Ls[e_idx], e_idx)
    G = sp.csr_matrix((w.astype(float), (rows, cols)), shape=(N * nq, N * nq))
    arcs = dict(zip(zip(rows.tolist(), cols.tolist()), e_idx.tolist()))
    return Product(G, arcs, succ, refused, N, nq)


def edge_arrays(ts, n_states: int, automaton: str, what: str) -> tuple:
    """``(src, dst, L)`` of the edges of ``ts``, each ``(E,)`` int64; a product with an ``n_states``-state
    ``automaton`` of more than :data:`MAX_PRODUCT_PAIRS` (edge, state) pairs is refused (simplify ``what``)."""
    E = ts.n_edges
    if E * n_states > MAX_PRODUCT_PAIRS:
        raise SpecificationError(f"the product of the {E:,} transitions with the {n_states:,}-state {automaton} "
                                 f"has {E * n_states:,} (edge, state) pairs; at most {MAX_PRODUCT_PAIRS:,} fit "
                                 f"in memory: simplify the {what}")
    a = ts.edge_arrays()
    return a.src, a.dst, a.L


def cheapest_arcs(rows, cols, w, e) -> tuple:
    """The cheapest arc ``(rows, cols, w, e)`` between each node pair (ties: the lowest edge id ``e``)."""
    order = np.lexsort((e, w, cols, rows))
    rows, cols, w, e = rows[order], cols[order], w[order], e[order]
    first = np.ones(len(rows), bool)
    first[1:] = (rows[1:] != rows[:-1]) | (cols[1:] != cols[:-1])
    return rows[first], cols[first], w[first], e[first]


def _initial_state(ts, dfa: DFA, start: int) -> int:
    """DFA state after the letter of ``x(0)``; raises if points of the start cell disagree."""
    states = sorted({int(dfa.delta[dfa.initial, s]) for s in start_letters(ts.decomposition, dfa.labels, start)})
    incl, live = dfa.inclusion(), dfa.live()
    best = [m for m in states if all(incl[m, r] for r in states)]
    if best and (live[best[0]] or not live[states].any()):
        return best[0]
    if len(states) > 1:
        must, may = cell_letters(ts.decomposition, dfa.labels, start)
        extra = [dfa.labels[b] for b in range(len(dfa.labels)) if (may & ~must) >> b & 1]
        raise PlanningError(f"start cell {start} touches region(s) {', '.join(extra)}: a start "
                            "state on the shared boundary would read a different letter; start "
                            "in a cell away from them")
    return states[0]


def plan_dfa(ts, start_cell: int, dfa: DFA, kind: str = "formula", letters=None,
             product: Product | None = None) -> SpecPlan:
    """Least-steps plan from ``start_cell`` whose every run is accepted by ``dfa`` (a :class:`SpecPlan` of
    ``kind``, ``plan.method == 'product'``, one segment ending at the last cell).

    ``letters`` (:func:`~.labelling.edge_letters` for ``dfa.labels``) and ``product`` (:func:`build_product`)
    are computed when not given. Raises :class:`PlanningError` for an unsatisfiable automaton or a start
    cell that violates it or touches a region that would, and :class:`NoPlanError` when no accepting
    node is reachable (:func:`~.plans.plan_formula` then says which part cannot be met).
    """
    t0 = time.perf_counter()
    start = _check_cell(ts, start_cell)
    if not dfa.satisfiable():
        raise PlanningError(f"the specification {dfa.description!r} is unsatisfiable: no "
                            "sequence of regions satisfies it")
    q0 = _initial_state(ts, dfa, start)
    if not dfa.live()[q0]:
        raise PlanningError(f"the specification {dfa.description!r} is already violated at "
                            f"the start cell {start} (label {ts.decomposition.labels[start]})")
    if product is None:
        product = build_product(ts, dfa, letters)
    N = ts.n_cells
    s = q0 * N + start
    dist, pred = dijkstra(product.graph, directed=True, indices=s, return_predecessors=True)
    acc = np.repeat(dfa.accepting, N)
    cand = np.where(acc & np.isfinite(dist), dist, np.inf)
    if not np.isfinite(cand).any():
        raise NoPlanError(f"no plan from cell {start} satisfies {dfa.description!r}")
    nodes = predecessor_path(pred, s, int(np.argmin(cand)))
    cells = [v % N for v in nodes]
    states = tuple(v // N for v in nodes)
    edges = [product.arc_edge[u, v] for u, v in zip(nodes[:-1], nodes[1:])]
    steps = [int(ts.edges[k].L) for k in edges]
    lab = ts.decomposition.labels
    plan = Plan(cells, edges, steps, [dfa.description], [len(cells) - 1], [[cells[-1]]],
                None if lab[start] is None else str(lab[start]), "product")
    stats = {"product_nodes": int(N * dfa.n_states), "product_arcs": int(product.graph.nnz),
             "dfa_states": dfa.n_states, "refused_edge_states": product.refused,
             "plan_steps": plan.cost, "seconds": time.perf_counter() - t0}
    return SpecPlan(plan, dfa, states, dfa.description, kind, tuple(avoided_labels(dfa)), stats)


def _reached(ts, dfa: DFA, start: int, product: Product) -> tuple[set, int]:
    """Cells reachable from the start in live product nodes, and the largest live DFA state id reached."""
    N = ts.n_cells
    q0 = _initial_state(ts, dfa, start)
    dist = dijkstra(product.graph, directed=True, indices=q0 * N + start)
    hit = np.flatnonzero(np.isfinite(dist))
    return {int(v % N) for v in hit}, int(max(v // N for v in hit))


def avoided_labels(dfa: DFA) -> list:
    """Labels ``a`` such that, from some reachable live state, entering region ``a`` kills the spec
    (a letter ``S`` of the alphabet holding ``a`` leads to a dead state while ``S`` without ``a`` does not)."""
    live, reach = dfa.live(), dfa.reachable()
    out = []
    ok = np.ones(dfa.n_letters, bool) if dfa.alphabet is None else dfa.alphabet
    for b, lab in enumerate(dfa.labels):
        S = np.array([s for s in range(dfa.n_letters) if s >> b & 1 and ok[s]], np.int64)
        if not S.size:
            continue
        qs = np.flatnonzero(live & reach)
        kill = ~live[dfa.delta[np.ix_(qs, S)]] & live[dfa.delta[np.ix_(qs, S & ~(1 << b))]]
        if kill.any():
            out.append(lab)
    return out
