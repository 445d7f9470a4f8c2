"""Deterministic finite automata over region letters.

A *letter* is the set of propositions true at one time step, stored as a bit
mask (bit ``b`` is proposition ``b`` of the automaton); a DFA is an explicit
table ``delta (n_states, 2**k)``. It reads the trace ``x(0), x(1), ..., x(T)``
one letter per state and accepts when it ends in an accepting state (LTLf).

:func:`dfa_from_formula` builds the DFA of a flloat LTLf formula with flloat's
own transition function (``formula.delta``, the alternating automaton of De
Giacomo and Vardi): the macrostates are sets of obligation sets, explored over
every letter, then minimised (Moore). flloat's ``to_automaton`` does the same
through sympy and takes seconds to minutes for four or five propositions; here
the minimal models of the (positive) successor formulas are computed directly,
which takes milliseconds. The tests check the result against flloat's
``to_automaton`` and against flloat's trace semantics (``formula.truth``).

:func:`sequence_dfa` is the automaton of "visit ``a``, then ``b``, then ...",
built directly (state ``k``: the first ``k`` targets visited).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .formula import SpecificationError

__all__ = ["DFA", "dfa_from_formula", "sequence_dfa", "MAX_PROPOSITIONS"]

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
    """

    propositions: tuple
    labels: tuple
    delta: np.ndarray
    initial: int
    accepting: np.ndarray
    description: str = ""

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
        live = self.accepting.copy()
        while True:
            new = live | live[self.delta].any(axis=1)
            if (new == live).all():
                return live
            live = new

    def inclusion(self) -> np.ndarray:
        """``(n_states, n_states)`` bool: ``[a, b]`` iff every trace accepted from ``a`` is accepted from ``b``.

        The greatest relation with ``a`` accepting => ``b`` accepting that is closed
        under every letter (computed by fixed-point iteration).
        """
        acc = self.accepting
        inc = ~acc[:, None] | acc[None, :]
        while True:
            new = inc & inc[self.delta[:, None, :], self.delta[None, :, :]].all(axis=-1)
            if (new == inc).all():
                return inc
            inc = new

    def reachable(self) -> np.ndarray:
        """``(n_states,)`` bool: reachable from the initial state over any letters."""
        seen = np.zeros(self.n_states, bool)
        seen[self.initial] = True
        while True:
            new = seen.copy()
            new[np.unique(self.delta[seen])] = True
            if (new == seen).all():
                return seen
            seen = new


def _minimal_models(pl) -> frozenset:
    """Minimal models of a positive propositional formula over flloat ``PLAtomic`` atoms.

    Returns a set of clauses (frozensets of the atoms' LTLf formulas); ``{frozenset()}``
    is *true*, the empty set *false*.
    """
    from flloat.pl import PLAnd, PLAtomic, PLFalse, PLOr, PLTrue

    if isinstance(pl, PLTrue):
        return frozenset({frozenset()})
    if isinstance(pl, PLFalse):
        return frozenset()
    if isinstance(pl, PLOr):
        out = frozenset().union(*(_minimal_models(f) for f in pl.formulas))
    elif isinstance(pl, PLAnd):
        out = frozenset({frozenset()})
        for f in pl.formulas:
            m = _minimal_models(f)
            out = frozenset(a | b for a in out for b in m)
            if not out:
                return out
    elif isinstance(pl, PLAtomic):
        return frozenset({frozenset({pl.s})})
    else:                                   # negations never reach here: delta resolves them
        raise TypeError(f"unexpected successor formula {pl!r} ({type(pl).__name__})")
    return _absorb(out)


def _absorb(clauses) -> frozenset:
    """Drop clauses that contain another clause (the minimal ones remain)."""
    cs = sorted(clauses, key=len)
    keep = []
    for c in cs:
        if not any(k <= c for k in keep):
            keep.append(c)
    return frozenset(keep)


def _accepts_empty(macro) -> bool:
    """A macrostate accepts the empty suffix: some clause whose obligations all hold at the end."""
    from flloat.pl import PLTrue
    return any(all(f.delta({}, epsilon=True) == PLTrue() for f in c) for c in macro)


def dfa_from_formula(parsed) -> DFA:
    """The minimal DFA of a :class:`~tubejax.spec.formula.ParsedFormula`.

    Parameters
    ----------
    parsed : ParsedFormula

    Returns
    -------
    DFA
        Over the formula's propositions (``parsed.propositions``).
    """
    from flloat.pl import PLAnd, PLTrue

    k = len(parsed.propositions)
    if k > MAX_PROPOSITIONS:
        raise SpecificationError(f"formula {parsed.text!r} uses {k} propositions; at most "
                                 f"{MAX_PROPOSITIONS} are supported (2**k letters)")
    letters = [{f"p{b}": True for b in range(k) if s >> b & 1} for s in range(1 << k)]
    start = frozenset({frozenset({parsed.ltlf.to_nnf()})})
    index, order, rows = {start: 0}, [start], []
    cache = {}
    q = 0
    while q < len(order):
        macro = order[q]
        row = []
        for s, interp in enumerate(letters):
            nxt = set()
            for clause in macro:
                key = (clause, s)
                if key not in cache:
                    ds = [f.delta(interp) for f in clause]
                    pl = PLTrue() if not ds else ds[0] if len(ds) == 1 else PLAnd(ds)
                    cache[key] = _minimal_models(pl)
                nxt |= cache[key]
            nxt = _absorb(nxt)
            if nxt not in index:
                index[nxt] = len(order)
                order.append(nxt)
            row.append(index[nxt])
        rows.append(row)
        q += 1
    delta = np.array(rows, dtype=np.int64).reshape(len(order), 1 << k)
    acc = np.array([_accepts_empty(m) for m in order])
    return _minimise(DFA(parsed.propositions, parsed.labels, delta, 0, acc, parsed.text))


def _minimise(d: DFA) -> DFA:
    """Moore's partition refinement; states renumbered in breadth-first order from the initial one."""
    cls = d.accepting.astype(np.int64)
    while True:
        sig = np.concatenate([cls[:, None], cls[d.delta]], axis=1)
        _, new = np.unique(sig, axis=0, return_inverse=True)
        new = new.ravel()
        if len(np.unique(new)) == len(np.unique(cls)):
            break
        cls = new
    # breadth-first renumbering (deterministic)
    rep = {}
    order = [int(cls[d.initial])]
    rep[order[0]] = 0
    first = {}
    for q in range(d.n_states):
        first.setdefault(int(cls[q]), q)
    i = 0
    while i < len(order):
        c = order[i]
        for s in range(d.n_letters):
            c2 = int(cls[d.delta[first[c], s]])
            if c2 not in rep:
                rep[c2] = len(order)
                order.append(c2)
        i += 1
    delta = np.array([[rep[int(cls[d.delta[first[c], s]])] for s in range(d.n_letters)]
                      for c in order], dtype=np.int64).reshape(len(order), d.n_letters)
    acc = np.array([bool(d.accepting[first[c]]) for c in order])
    return DFA(d.propositions, d.labels, delta, 0, acc, d.description)


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
        Names for the distinct labels (default ``l<label>`` or the label itself).

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
    bit = {l: b for b, l in enumerate(distinct)}
    K = len(labels)
    delta = np.empty((K + 1, 1 << len(distinct)), dtype=np.int64)
    for q in range(K + 1):
        for s in range(1 << len(distinct)):
            k = q
            while k < K and s >> bit[labels[k]] & 1:
                k += 1
            delta[q, s] = k
    acc = np.zeros(K + 1, bool)
    acc[K] = True
    props = tuple(propositions) if propositions is not None else tuple(f"l{l}" for l in distinct)
    return DFA(props, tuple(distinct), delta, 0, acc, " -> ".join(labels))
