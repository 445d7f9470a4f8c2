"""Deterministic finite automata over region letters.

A *letter* is the set of propositions true at one time step, a bit mask (bit ``b``: proposition
``b``); a DFA is a table ``delta (n_states, 2**k)`` that reads the trace ``x(0) .. x(T)`` and accepts
when it ends in an accepting state (LTLf). :func:`sequence_dfa` is "visit ``a``, then ``b``, ...";
formulas go through Spot (:func:`~tubejax.analyses.spec.automata.dfa_from_formula`);
:func:`minimise` is Moore's partition refinement.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order

from .formula import SpecificationError, proposition_of

__all__ = ["DFA", "sequence_dfa", "minimise", "MAX_PROPOSITIONS"]

#: Most propositions one formula may use (the alphabet has ``2**k`` letters).
MAX_PROPOSITIONS = 12


@dataclass(frozen=True, eq=False)
class DFA:
    """An explicit DFA over bit-mask letters.

    Attributes
    ----------
    propositions : tuple of str
        Proposition of each letter bit (``'l3'``, ...), length ``k``.
    labels : tuple of str
        Region label of each proposition, length ``k``.
    delta : ndarray of int, shape (n_states, 2**k)
        ``delta[q, letter]`` is the successor state.
    initial : int
    accepting : ndarray of bool, shape (n_states,)
    description : str
        The formula or sequence it was built from.
    alphabet : ndarray of bool, shape (2**k,), optional
        The letters the automaton was built for (``None``: all); any other letter
        leads to a rejecting sink.
    """

    propositions: tuple
    labels: tuple
    delta: np.ndarray
    initial: int
    accepting: np.ndarray
    description: str = ""
    alphabet: np.ndarray | None = None

    @property
    def n_states(self) -> int:
        return int(self.delta.shape[0])

    @property
    def n_letters(self) -> int:
        return int(self.delta.shape[1])

    def letter(self, labels) -> int:
        """The bit mask of a set of region labels (labels without a proposition are ignored)."""
        idx = {l: b for b, l in enumerate(self.labels)}
        return int(sum(1 << idx[str(l)] for l in set(map(str, labels)) if str(l) in idx))

    def cell_states(self, cell_labels, cells) -> tuple:
        """The state after each cell of the path ``cells`` (one letter each: the cell's label, ``cell_labels[c]``)."""
        letters = [self.letter([] if cell_labels[c] is None else [cell_labels[c]]) for c in cells]
        return tuple(int(s) for s in self.run(np.array(letters)))

    def run(self, letters, state: int | None = None) -> np.ndarray:
        """States after each letter: ``letters (..., T)`` int -> ``(..., T)`` (vectorised over runs)."""
        L = np.asarray(letters, dtype=np.int64)
        q = np.full(L.shape[:-1], self.initial if state is None else state, dtype=np.int64)
        out = np.empty(L.shape, dtype=np.int64)
        for t in range(L.shape[-1]):
            q = self.delta[q, L[..., t]]
            out[..., t] = q
        return out

    def accepts(self, letters) -> np.ndarray:
        """Whether each trace ``letters (..., T)`` (``T >= 1``) is accepted, shape ``(...)``."""
        return self.accepting[self.run(letters)[..., -1]]

    def live(self) -> np.ndarray:
        """``(n_states,)`` bool: an accepting state is reachable (the spec can still be met)."""
        return _closure(self.delta, self.accepting, backward=True)

    def inclusion(self) -> np.ndarray:
        """``(n_states, n_states)`` bool: ``[a, b]`` iff every trace accepted from ``a`` is accepted from ``b``.

        The greatest relation with ``a`` accepting => ``b`` accepting that is closed
        under every letter of the alphabet (fixed-point iteration; the other letters
        lead both to the rejecting sink).
        """
        acc = self.accepting
        inc = ~acc[:, None] | acc[None, :]
        cols = range(self.n_letters) if self.alphabet is None else np.flatnonzero(self.alphabet)
        while True:
            new = inc.copy()
            for s in cols:
                d = self.delta[:, s]
                new &= inc[d[:, None], d[None, :]]
            if (new == inc).all():
                return inc
            inc = new

    def satisfiable(self) -> bool:
        """Whether an accepting state is reachable (the automaton accepts some trace)."""
        return bool((self.accepting & self.reachable()).any())

    def reachable(self) -> np.ndarray:
        """``(n_states,)`` bool: reachable from the initial state over any letters."""
        seen = np.zeros(self.n_states, bool)
        seen[self.initial] = True
        return _closure(self.delta, seen, backward=False)


def _closure(delta: np.ndarray, start: np.ndarray, backward: bool) -> np.ndarray:
    """States reachable from ``start`` (``backward``: that reach it) over ``delta``: one breadth-first
    search from an extra node ``n`` with arcs to ``start`` (a patrol's sequence automaton is a chain of
    tens of thousands of states)."""
    n, m = delta.shape
    seeds = np.flatnonzero(start)
    src, dst = np.repeat(np.arange(n), m), delta.ravel()
    if backward:
        src, dst = dst, src
    src, dst = np.concatenate([src, np.full(len(seeds), n)]), np.concatenate([dst, seeds])
    adj = sp.csr_matrix((np.ones(src.size, bool), (src, dst)), shape=(n + 1, n + 1))
    seen = np.zeros(n + 1, bool)
    seen[breadth_first_order(adj, n, directed=True, return_predecessors=False)] = True
    return seen[:n]


def sequence_dfa(labels, propositions=None) -> DFA:
    """DFA of "visit ``labels[0]``, then ``labels[1]``, ..." (``F(a & F(b & ...))``).

    State ``k`` means the first ``k`` targets are visited; a letter holding the
    next target advances, repeatedly (a state on a shared boundary of the next two
    targets visits both, as in LTLf). Labels may repeat.

    Parameters
    ----------
    labels : sequence of str
        Target labels in order, length ``K >= 1``.
    propositions : sequence of str, optional
        Names for the distinct labels (default: ``l<label>``, or the label itself when it cannot be named).

    Returns
    -------
    DFA
        ``K + 1`` states, state ``K`` accepting (and absorbing).
    """
    labels = [str(l) for l in labels]
    if not labels:
        raise SpecificationError("sequence: give at least one target label")
    distinct = sorted(set(labels))
    if len(distinct) > MAX_PROPOSITIONS:
        raise SpecificationError(f"sequence: {len(distinct)} distinct labels; at most "
                                 f"{MAX_PROPOSITIONS} are supported")
    bit = np.array([distinct.index(l) for l in labels], dtype=np.int64)
    K = len(labels)
    delta = np.empty((K + 1, 1 << len(distinct)), dtype=np.int64)
    for s in range(1 << len(distinct)):           # from q, the first target at or after q not in s
        miss = np.where((s >> bit & 1) == 0, np.arange(K), K)
        delta[:K, s] = np.minimum.accumulate(miss[::-1])[::-1]
        delta[K, s] = K
    acc = np.zeros(K + 1, bool)
    acc[K] = True
    props = tuple(propositions) if propositions is not None else tuple(proposition_of(l) or l for l in distinct)
    return DFA(props, tuple(distinct), delta, 0, acc, " -> ".join(labels))


def minimise(d: DFA) -> DFA:
    """Moore's partition refinement; states renumbered in breadth-first order from the initial one."""
    cls = d.accepting.astype(np.int64)
    while True:
        _, new = np.unique(np.concatenate([cls[:, None], cls[d.delta]], axis=1), axis=0, return_inverse=True)
        if len(np.unique(new)) == len(np.unique(cls)):
            break
        cls = new.ravel()
    _, first, cls = np.unique(cls, return_index=True, return_inverse=True)
    quot = cls.ravel()[d.delta[first]]                 # (classes, letters): the quotient's table
    order = [int(cls.ravel()[d.initial])]
    rank = np.full(len(first), -1)
    rank[order[0]] = 0
    for c in order:                                    # breadth first (the list grows as it is read)
        for c2 in quot[c].tolist():
            if rank[c2] < 0:
                rank[c2] = len(order)
                order.append(c2)
    return DFA(d.propositions, d.labels, rank[quot[order]], 0, d.accepting[first[order]], d.description,
               d.alphabet)
