"""Plans over infinite runs: the sound product with a Büchi automaton and its cheapest accepting lasso
(docs/math/control.md#ltl-over-infinite-runs).

Node ``(cell i, automaton state q)`` is ``q * N + i``; for a nondeterministic automaton the states
reachable for some letter sequence are tracked as bit sets (:func:`buchi_successors`). Ties go to the
lowest node id, then the lowest arc.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, dijkstra

from ..control.planner import predecessor_path
from .automata import Buchi
from .labelling import EdgeLetters, map_alphabet, start_letters, submasks
from .product import cheapest_arcs, edge_arrays

__all__ = ["BuchiProduct", "Lasso", "buchi_successors", "direct_simulation", "build_buchi_product", "initial_states", "cheapest_lasso"]

#: Sources per batch of the many-source Dijkstra (a batch holds ``batch x nodes`` distances).
_BATCH = 256


def direct_simulation(buchi: Buchi, alphabet) -> list:
    """``down[r]``: bit set of the states ``m`` that ``r`` directly simulates, over the letters of ``alphabet``.

    The greatest relation with ``m`` accepting => ``r`` accepting such that every move of ``m``
    on a letter is matched by a move of ``r`` on it to a state simulating the target
    (fixed-point iteration over boolean matrices, ``(n, n)`` per letter).
    """
    n = buchi.n_states
    lets = np.flatnonzero(np.asarray(alphabet, bool)).tolist()
    post = [np.array([[bool(buchi.post[q][s] >> t & 1) for t in range(n)] for q in range(n)], np.int64)
            for s in lets]
    acc = buchi.accepting
    sim = ~acc[None, :] | acc[:, None]                          # sim[r, m]
    while True:
        new = sim.copy()
        for P in post:
            X = (P @ sim.astype(np.int64)) > 0                    # X[r, m']: r moves to a simulator of m'
            new &= ((~X).astype(np.int64) @ P.T) == 0              # every move of m is matched
        if (new == sim).all():
            return [sum(1 << m for m in np.flatnonzero(sim[r]).tolist()) for r in range(n)]
        sim = new


def _down(bits: int, down: list) -> int:
    out, r = 0, 0
    while bits:
        if bits & 1:
            out |= down[r]
        bits >>= 1
        r += 1
    return out


def buchi_successors(buchi: Buchi, letters: EdgeLetters, alphabet) -> tuple[np.ndarray, np.ndarray]:
    """``(plain, accepting)``, each ``(E, n_states)`` object arrays of bit sets (module docstring).

    ``plain[e, q]``: states ``m`` such that for every letter sequence of edge ``e`` a state
    simulating ``m`` is reachable from ``q``; ``accepting[e, q]``: those for which it is reachable
    through an accepting state.
    Edges with the same letter sets share the work.
    """
    E, nq = len(letters.L), buchi.n_states
    plain = np.zeros((E, nq), object)
    accept = np.zeros((E, nq), object)
    if E == 0:
        return plain, accept
    keys, inv = letters.distinct()
    ok = np.asarray(alphabet, bool)
    accbits = buchi.accepting_bits
    down = direct_simulation(buchi, ok)
    step_letters = {}
    res_p = np.zeros((len(keys), nq), object)
    res_a = np.zeros((len(keys), nq), object)
    for u, key in enumerate(keys):
        steps = []
        for must, may in key:
            if (must, may) not in step_letters:
                step_letters[must, may] = [must | s for s in submasks(may & ~must) if ok[must | s]]
            steps.append(step_letters[must, may])
        for q in range(nq):
            macros = {(1 << q, 0)}
            for lets in steps:
                new = set()
                for P, A in macros:
                    for S in lets:
                        P2 = buchi.step(P, S)
                        new.add((P2, buchi.step(A, S) | (P2 & accbits)))
                macros = new
                if len(macros) == 1 and next(iter(macros))[0] == 0:
                    break
            if not macros:                            # no letter can occur: nothing is promised
                continue
            allp = alla = -1
            for P, A in macros:
                allp &= _down(P, down)
                alla &= _down(A, down)
            res_p[u, q], res_a[u, q] = allp, alla
    return res_p[inv], res_a[inv]


def initial_states(ts, buchi: Buchi, start: int) -> int:
    """Bit set of the states ``m`` such that every letter ``x(0)`` can read in the start cell leads
    to a state simulating ``m``."""
    down = direct_simulation(buchi, map_alphabet(ts.decomposition, buchi.labels))
    out = -1
    for s in start_letters(ts.decomposition, buchi.labels, start):
        out &= _down(buchi.post[buchi.initial][s], down)
    return max(out, 0)


@dataclass(frozen=True, eq=False)
class BuchiProduct:
    """The product graph of a transition system with a Büchi automaton.

    Attributes
    ----------
    graph : scipy.sparse.csr_matrix, shape (n_states * N, n_states * N)
        The cheapest arc between each pair of nodes (weights ``L``).
    acc_rows, acc_cols, acc_w, acc_edge : ndarray, shape (A,)
        The accepting arcs (the cheapest accepting one per node pair) and their edges.
    arc_edge : dict
        ``{(u, v): edge index}`` of the cheapest edge behind each arc of ``graph``.
    refused : int
        Pairs (edge, state) from which the edge promises no state.
    """

    graph: sp.csr_matrix
    acc_rows: np.ndarray
    acc_cols: np.ndarray
    acc_w: np.ndarray
    acc_edge: np.ndarray
    arc_edge: dict
    refused: int
    n_cells: int
    n_states: int


def build_buchi_product(ts, buchi: Buchi, letters: EdgeLetters) -> BuchiProduct:
    """The product of ``ts`` (all edges) with ``buchi`` (module docstring).

    Raises
    ------
    SpecificationError
        More than :data:`~.product.MAX_PRODUCT_PAIRS` (edge, state) pairs (:func:`~.product.edge_arrays`).
    """
    N, nq = ts.n_cells, buchi.n_states
    src, dst, Ls = edge_arrays(ts, nq, f"Büchi automaton of {buchi.description!r}", "formula")
    plain, accept = buchi_successors(buchi, letters, map_alphabet(ts.decomposition, buchi.labels))
    r, c, w, ed, acc = [], [], [], [], []
    refused = 0
    for q2 in range(nq):
        bit = 1 << q2
        has = np.frompyfunc(lambda x, b=bit: bool(x & b), 1, 1)
        P = has(plain).astype(bool)                               # (E, nq)
        A = has(accept).astype(bool)
        e_idx, q_idx = np.nonzero(P)
        r.append(q_idx * N + src[e_idx]); c.append(q2 * N + dst[e_idx]); w.append(Ls[e_idx])
        ed.append(e_idx); acc.append(A[e_idx, q_idx])
    refused = int((plain == 0).sum())
    rows, cols, w, e_all, acc = (np.concatenate(x) for x in (r, c, w, ed, acc))
    gr, gc, gw, ge = cheapest_arcs(rows, cols, w, e_all)
    G = sp.csr_matrix((gw.astype(float), (gr, gc)), shape=(N * nq, N * nq))
    ar, ac, aw, ae = cheapest_arcs(rows[acc], cols[acc], w[acc], e_all[acc])
    arcs = dict(zip(zip(gr.tolist(), gc.tolist()), ge.tolist()))
    return BuchiProduct(G, ar, ac, aw, ae, arcs, refused, N, nq)


@dataclass(frozen=True)
class Lasso:
    """A prefix and a cycle of product nodes (``q * N + i``) and the edges between them.

    ``prefix_nodes[-1] == cycle_nodes[0] == cycle_nodes[-1]``; ``cycle_edges`` has one edge
    per cycle arc, the accepting one among them.
    """

    prefix_nodes: list
    prefix_edges: list
    cycle_nodes: list
    cycle_edges: list
    prefix_steps: int
    cycle_steps: int

    def unrolled(self, n_cells: int, cycles: int) -> tuple[list, list, list, list]:
        """``(prefix cells, cycle cells, cells, edges)``: the prefix, then the cycle ``cycles`` times."""
        pcells = [int(v % n_cells) for v in self.prefix_nodes]
        ccells = [int(v % n_cells) for v in self.cycle_nodes]
        return (pcells, ccells, pcells + ccells[1:] * int(cycles),
                list(self.prefix_edges) + list(self.cycle_edges) * int(cycles))


def cheapest_lasso(prod: BuchiProduct, starts, anchors=None) -> Lasso | None:
    """The cheapest accepting lasso from any node of ``starts`` (module docstring); ``None`` if there is none.

    ``anchors`` (``(n_nodes,)`` bool, optional): the cycle must begin at one of these nodes (a
    patrol's cycle begins in its first region); the cheapest cycle through an anchor is taken.
    """
    G = prod.graph
    starts = sorted(int(s) for s in starts)
    if not starts or not len(prod.acc_rows):
        return None
    d0, pred0, src0 = dijkstra(G, directed=True, indices=starts, min_only=True, return_predecessors=True)
    _, scc = connected_components(G, directed=True, connection="strong")
    u, v, w = prod.acc_rows, prod.acc_cols, prod.acc_w.astype(float)
    keep = np.isfinite(d0[u]) & (scc[u] == scc[v])
    if not keep.any():
        return None
    u, v, w, arc_ids = u[keep], v[keep], w[keep], np.flatnonzero(keep)
    if anchors is None:
        heads = np.unique(v)
        cyc = np.full(len(u), np.inf)
        for i in range(0, len(heads), _BATCH):
            hs = heads[i:i + _BATCH]
            D = dijkstra(G, directed=True, indices=hs)
            sel = np.isin(v, hs)
            cyc[sel] = w[sel] + D[np.searchsorted(hs, v[sel]), u[sel]]
        best = cyc.min()
        if not np.isfinite(best):
            return None
        cand = np.flatnonzero(cyc == best)
        allowed = np.ones(G.shape[0], bool)
    else:
        cand, best, allowed = np.arange(len(u)), None, np.asarray(anchors, bool)
    # nodes on a cheapest cycle through a candidate arc: d(v, x) + d(x, u) + w == best
    GT = G.T.tocsr()
    choice = None                                  # (cycle cost, prefix cost, node, arc)
    for i in range(0, len(cand), _BATCH):
        cs = cand[i:i + _BATCH]
        through = dijkstra(G, directed=True, indices=v[cs]) + dijkstra(GT, directed=True, indices=u[cs]) + w[cs, None]
        through[:, ~(allowed & np.isfinite(d0))] = np.inf
        if best is not None:
            through[through != best] = np.inf
        pre = np.where(np.isfinite(through), d0[None, :], np.inf)
        order = np.lexsort((np.arange(through.size), pre.ravel(), through.ravel()))[0]
        k, x = np.unravel_index(order, through.shape)
        c = (float(through[k, x]), float(pre[k, x]), int(x), int(cs[k]))
        if np.isfinite(c[0]) and (choice is None or c < choice):
            choice = c
    if choice is None:
        return None
    best, pcost, x, a = choice
    ua, va = int(u[a]), int(v[a])
    _, pred_x = dijkstra(G, directed=True, indices=x, return_predecessors=True)
    _, pred_v = dijkstra(G, directed=True, indices=va, return_predecessors=True)
    first = predecessor_path(pred_x, x, ua)
    back = predecessor_path(pred_v, va, x)
    cycle = first + back
    acc_edge = int(prod.acc_edge[arc_ids[a]])
    cedges = ([prod.arc_edge[p, q] for p, q in zip(first[:-1], first[1:])] + [acc_edge]
              + [prod.arc_edge[p, q] for p, q in zip(back[:-1], back[1:])])
    s = int(src0[x])
    prefix = predecessor_path(pred0, s, x)
    pedges = [prod.arc_edge[p, q] for p, q in zip(prefix[:-1], prefix[1:])]
    return Lasso(prefix, pedges, cycle, cedges, int(pcost), int(best))
