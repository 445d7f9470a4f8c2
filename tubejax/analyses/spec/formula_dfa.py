"""The minimal DFA of an LTLf formula, built with flloat's own transition function.

:func:`dfa_from_formula` builds the DFA of a flloat LTLf formula with flloat's
own transition function (``formula.delta``, the alternating automaton of De
Giacomo and Vardi): the macrostates are sets of obligation sets, explored over
every letter, then minimised (Moore). flloat's ``to_automaton`` does the same
through sympy and takes seconds to minutes for four or five propositions; here
the minimal models of the (positive) successor formulas are computed directly,
which takes milliseconds. The tests check the result against flloat's
``to_automaton`` and against flloat's trace semantics (``formula.truth``). The
limits below bound the construction and the size of the automaton it returns.
"""

from __future__ import annotations

import numpy as np
from flloat.pl import PLAnd, PLAtomic, PLFalse, PLOr, PLTrue
from flloat.ltlf import LTLfAlways, LTLfEventually, LTLfNext, LTLfRelease, LTLfUntil, LTLfWeakNext

from .dfa import DFA, MAX_PROPOSITIONS, minimise
from .formula import SpecificationError, _short

__all__ = ["flloat_dfa", "MAX_DFA_STATES", "MAX_EXPLORED_STATES", "MAX_CONSTRUCTION_WORK"]

#: Most states of a formula's minimal DFA: the product and the language-inclusion test
#: grow with the square of this (``F(l3 & X ... X l5)`` has 1,025 states with 10 ``X`` and
#: 2,049 with 11; visiting ``m`` regions in any order needs ``2**m``); bigger automata are
#: refused with their size.
MAX_DFA_STATES = 2048
#: Most (unminimised) states explored while building one DFA; the construction stops
#: there and refuses the formula, before memory grows (``F(l3 & X X ... X l5)`` with
#: ``m`` ``X`` needs about ``2**m`` states).
MAX_EXPLORED_STATES = 16384
#: Most elementary steps (clause unions and subset tests of the successor models) one
#: construction may take, seconds (up to about 15 s for formulas nested 64 deep); formulas
#: that nest many ``F``/``G``/``U``/``R`` make the obligation sets grow exponentially and
#: are refused when they reach it. Everyday formulas take a few thousand steps.
MAX_CONSTRUCTION_WORK = 10_000_000


class _TooBig(Exception):
    """The construction reached :data:`MAX_CONSTRUCTION_WORK` (caught in :func:`dfa_from_formula`)."""


class _Meter:
    """Counts the elementary steps of one construction; raises :class:`_TooBig` past the budget."""

    def __init__(self, budget: int):
        self.budget, self.spent = int(budget), 0

    def charge(self, n: int):
        self.spent += n
        if self.spent > self.budget:
            raise _TooBig


def _minimal_models(pl, meter: _Meter) -> frozenset:
    """Minimal models of a positive propositional formula over flloat ``PLAtomic`` atoms.

    Returns a set of clauses (frozensets of the atoms' LTLf formulas); ``{frozenset()}``
    is *true*, the empty set *false*. Every clause built is charged to ``meter``.
    """

    if isinstance(pl, PLTrue):
        return frozenset({frozenset()})
    if isinstance(pl, PLFalse):
        return frozenset()
    if isinstance(pl, PLOr):
        out = frozenset().union(*(_minimal_models(f, meter) for f in pl.formulas))
    elif isinstance(pl, PLAnd):
        out = frozenset({frozenset()})
        for f in pl.formulas:
            m = _minimal_models(f, meter)
            meter.charge(len(out) * len(m))
            out = frozenset(a | b for a in out for b in m)
            if not out:
                return out
    elif isinstance(pl, PLAtomic):
        return frozenset({frozenset({pl.s})})
    else:                                   # negations never reach here: delta resolves them
        raise TypeError(f"unexpected successor formula {pl!r} ({type(pl).__name__})")
    return _absorb(out, meter)


def _absorb(clauses, meter: _Meter | None = None) -> frozenset:
    """Drop clauses that contain another clause (the minimal ones remain); subset tests charged to ``meter``."""
    cs = sorted(clauses, key=len)
    keep = []
    for c in cs:
        if meter is not None:
            meter.charge(len(keep) + 1)
        if not any(k <= c for k in keep):
            keep.append(c)
    return frozenset(keep)


class _Obligations:
    """LTLf subformulas interned as integers, with memoised successor models.

    Comparing flloat formulas is a deep structural walk, so every distinct
    subformula gets an id once and the construction works on sets of ids.
    """

    def __init__(self, k: int, meter: _Meter):
        self.meter = meter
        self.ids, self.forms = {}, []
        self.letters = [{f"p{b}": True for b in range(k) if s >> b & 1} for s in range(1 << k)]
        self._models, self._clause, self._end = {}, {}, {}

    def intern(self, f) -> int:
        i = self.ids.get(f)
        if i is None:
            i = self.ids[f] = len(self.forms)
            self.forms.append(f)
        return i

    def models(self, i: int, s: int) -> frozenset:
        """Minimal models (sets of obligation ids) of ``delta(forms[i], letter s)``."""
        key = (i, s)
        if key not in self._models:
            mm = _minimal_models(self.forms[i].delta(self.letters[s]), self.meter)
            self._models[key] = frozenset(frozenset(self.intern(f) for f in c) for c in mm)
        return self._models[key]

    def step(self, clause: frozenset, s: int) -> frozenset:
        """Minimal models of the conjunction of the clause's successors."""
        key = (clause, s)
        if key not in self._clause:
            out = frozenset({frozenset()})
            for i in clause:
                m = self.models(i, s)
                self.meter.charge(len(out) * len(m))
                out = _absorb(frozenset(a | b for a in out for b in m), self.meter)
                if not out:
                    break
            self._clause[key] = out
        return self._clause[key]

    def accepts_empty(self, macro) -> bool:
        """Some clause whose obligations all hold on the empty suffix."""
        for i in {i for c in macro for i in c}:
            if i not in self._end:
                self._end[i] = self.forms[i].delta({}, epsilon=True) == PLTrue()
        return any(all(self._end[i] for i in c) for c in macro)


def flloat_dfa(parsed, alphabet=None) -> DFA:
    """The minimal DFA of a :class:`~tubejax.analyses.spec.formula.ParsedFormula`.

    Parameters
    ----------
    parsed : ParsedFormula
    alphabet : ndarray of bool, shape (2**k,), optional
        Only these letters are explored (e.g. :func:`~tubejax.analyses.spec.labelling.map_alphabet`:
        the letters a state can read on the map); the others lead to a rejecting sink.
        The construction is exponential in the number of letters explored, so this
        keeps formulas over many regions fast. Default: all ``2**k`` letters.

    Returns
    -------
    DFA
        Over the formula's propositions (``parsed.propositions``).

    Raises
    ------
    SpecificationError
        More than :data:`MAX_PROPOSITIONS` propositions, or an automaton too big to
        build or use: more than :data:`MAX_EXPLORED_STATES` states explored (fewer
        with many propositions: at most ``2**22`` table entries), more than
        :data:`MAX_CONSTRUCTION_WORK` steps, or more than :data:`MAX_DFA_STATES`
        states once minimal. The construction stops at the limit, before memory
        grows; the message gives the size reached and the limit.
    """
    k = len(parsed.propositions)
    if k > MAX_PROPOSITIONS:
        raise SpecificationError(f"formula {parsed.text!r} uses {k} propositions; at most "
                                 f"{MAX_PROPOSITIONS} are supported (2**k letters)")
    ok = np.ones(1 << k, bool) if alphabet is None else np.asarray(alphabet, bool)
    if ok.shape != (1 << k,):
        raise ValueError(f"alphabet: expected shape ({1 << k},), got {ok.shape}")
    limit = min(MAX_EXPLORED_STATES, _MAX_TABLE >> k)
    ob = _Obligations(k, _Meter(MAX_CONSTRUCTION_WORK))
    index, order, rows = {}, [], []
    try:
        start = frozenset({frozenset({ob.intern(parsed.ltlf.to_nnf())})})
        index[start] = 0
        order.append(start)
        q = 0
        while q < len(order):
            macro = order[q]
            row = np.empty(1 << k, np.int64)
            for s in range(1 << k):
                if not ok[s]:                      # the empty disjunction: false, the rejecting sink
                    nxt = frozenset()
                else:
                    nxt = _absorb(frozenset().union(*(ob.step(c, s) for c in macro)), ob.meter)
                if nxt not in index:
                    if len(order) == limit:
                        raise SpecificationError(_too_big(
                            parsed, f"its automaton needs more than {limit:,} states (the "
                                    f"construction stops there; at most {MAX_DFA_STATES:,} are supported)"))
                    index[nxt] = len(order)
                    order.append(nxt)
                row[s] = index[nxt]
            rows.append(row)
            q += 1
        acc = np.array([ob.accepts_empty(m) for m in order])
    except _TooBig:
        raise SpecificationError(_too_big(
            parsed, f"building its automaton takes more than {MAX_CONSTRUCTION_WORK:,} steps (the "
                    f"limit; {len(order):,} states found by then)")) from None
    delta = np.stack(rows)
    d = minimise(DFA(parsed.propositions, parsed.labels, delta, 0, acc, parsed.text,
                      None if alphabet is None else ok))
    if d.n_states > MAX_DFA_STATES:
        raise SpecificationError(_too_big(parsed, f"its minimal automaton has {d.n_states:,} states; "
                                                  f"at most {MAX_DFA_STATES:,} are supported"))
    return d


#: Most entries of the unminimised transition table (states x letters) one construction may fill.
_MAX_TABLE = 1 << 22


def _too_big(parsed, what: str) -> str:
    """The refusal of a formula whose automaton is too big, with a hint on the usual cause."""
    m = _next_depth(parsed.ltlf)
    hint = (f"; it nests {m} X/WX operators inside F, G, U or R, so the automaton has to remember "
            f"the last {m} steps: about 2^{m} = {2 ** m:,} states" if m >= 8 else "")
    return (f"formula {_short(parsed.text)!r}: {what}{hint}. Simplify the formula (fewer nested operators, "
            "or spec.sequence for a long visiting order)")


def _next_depth(f) -> int:
    """Most ``X``/``WX`` nested on one path inside an ``F``, ``G``, ``U`` or ``R`` (iterative walk)."""

    best, todo = 0, [(f, False, 0)]
    while todo:
        g, under, n = todo.pop()
        if isinstance(g, (LTLfNext, LTLfWeakNext)):
            n += 1
        if isinstance(g, (LTLfAlways, LTLfEventually, LTLfRelease, LTLfUntil)):
            under, n = True, 0
        if under:
            best = max(best, n)
        kids = getattr(g, "formulas", None) or ((g.f,) if hasattr(g, "f") else ())
        todo.extend((c, under, n) for c in kids)
    return best
