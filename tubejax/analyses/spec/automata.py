"""Automata of temporal formulas, built by Spot: DFAs of LTLf formulas, Büchi automata of LTL formulas.

:func:`dfa_from_formula` rewrites the LTLf tree (:mod:`.ltlf`) for Spot, which translates it
(``spot.from_ltlf``, a deterministic Büchi automaton, ``spot.to_finite``); the table over bit-mask
letters (bit ``b``: ``propositions[b]``) is completed with a rejecting sink and minimised.
:func:`buchi_from_formula` is Spot's state-based Büchi automaton of an LTL formula. Size limits
(docs/howto/formulas.md#a-formula) are enforced before memory grows (:func:`too_big`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import spot
from spot import buddy
from .ltlf import (LTLfAlways, LTLfAtomic, LTLfEquivalence, LTLfEventually, LTLfFalse, LTLfImplies, LTLfLast,
                   LTLfNext, LTLfNot, LTLfRelease, LTLfTrue, LTLfUntil, LTLfWeakNext)

from .dfa import DFA, MAX_PROPOSITIONS, minimise
from .formula import SpecificationError, _short

__all__ = ["Buchi", "dfa_from_formula", "buchi_from_formula", "spot_ltlf", "letter_sets",
           "MAX_DFA_STATES", "MAX_BUCHI_STATES", "too_big"]

#: Most states of a formula's minimal DFA: the product and the language-inclusion test
#: grow with the square of this (``F(l3 & X ... X l5)`` has 1,025 states with 10 ``X`` and
#: 2,049 with 11; visiting ``m`` regions in any order needs ``2**m``); bigger automata are
#: refused with their size.
MAX_DFA_STATES = 2048
#: Most states of an LTL formula's Büchi automaton (the product pairs every edge with
#: every state, and sound arcs track the sets of states a tube's letters can lead to).
MAX_BUCHI_STATES = 512
#: Spot's own cap on the powerset construction of its WDBA minimisation (Spot's ``-x``
#: option): beyond it Spot gives up determinising and returns what it has, which is then
#: refused by size or determinism.
_SPOT_CAPS = "wdba-det-max={n}"
#: Spot's operator codes for the weak and the strong next (``X`` and ``X[!]``).
_OP_X, _OP_STRONG_X = spot.formula("X a").kind(), spot.formula("X[!] a").kind()
_SPOT_UNARY = {LTLfNot: "!", LTLfNext: "X[!]", LTLfWeakNext: "X", LTLfEventually: "F", LTLfAlways: "G"}


# ----------------------------------------------------------------------------- formulas

def spot_ltlf(parsed) -> spot.formula:
    """The LTLf formula of a :class:`~tubejax.analyses.spec.formula.ParsedFormula` as a Spot formula over
    the user's propositions, with the semantics of :mod:`.ltlf` (``X`` is Spot's ``X[!]``, ``WX`` Spot's
    ``X``, ``last`` is ``X false``), written fully parenthesised and parsed by Spot."""
    def text(f) -> str:
        t = type(f)
        if t is LTLfAtomic:
            return parsed.propositions[int(f.s[1:])]
        if t in (LTLfTrue, LTLfFalse):
            return f.s
        if t is LTLfLast:
            return "X(false)"
        if t in _SPOT_UNARY:
            return f"{_SPOT_UNARY[t]}({text(f.f)})"
        a = [text(g) for g in f.formulas]
        if t is LTLfImplies:
            return functools.reduce(lambda x, y: f"({x} -> {y})", a)
        if t is LTLfEquivalence:
            return f"(({' & '.join(a)}) | ({' & '.join('!' + x for x in a)}))"
        if t in (LTLfUntil, LTLfRelease):
            return functools.reduce(lambda y, x: f"({x} {t.symbol} {y})", reversed(a))
        return "(" + f" {t.symbol} ".join(a) + ")"                  # & and |

    return spot.formula(text(parsed.ltlf))


def next_depth(f: spot.formula) -> int:
    """Most ``X`` nested on one path inside an ``F``, ``G``, ``U``, ``R``, ``W`` or ``M`` (iterative)."""
    temporal = {spot.op_F, spot.op_G, spot.op_U, spot.op_R, spot.op_W, spot.op_M}
    nexts = {_OP_X, _OP_STRONG_X}
    best, todo = 0, [(f, False, 0)]
    while todo:
        g, under, n = todo.pop()
        if g.kind() in nexts:
            n += 1
        if g.kind() in temporal:
            under, n = True, 0
        if under:
            best = max(best, n)
        todo.extend((c, under, n) for c in g)
    return best


def _holds_on_empty(f: spot.formula) -> bool:
    """The value of an LTLf formula on the empty trace, as the retired flloat defined it (bottom up
    over the negation normal form): literals, strong ``X``, ``F`` and ``U`` are false; weak ``X``,
    ``G`` and ``R`` are true."""
    val = {}
    todo = [(spot.negative_normal_form(f), False)]
    while todo:
        g, done = todo.pop()
        kids = list(g)
        if not done and kids:
            todo.append((g, True))
            todo.extend((c, False) for c in kids)
            continue
        k = g.kind()
        if k == spot.op_And:
            v = all(val[c.id()] for c in kids)
        elif k == spot.op_Or:
            v = any(val[c.id()] for c in kids)
        else:
            v = k in (spot.op_tt, _OP_X, spot.op_G, spot.op_R, spot.op_W)
        val[g.id()] = v
    return val[spot.negative_normal_form(f).id()]


def too_big(text: str, f: spot.formula, what: str) -> str:
    """The refusal of a formula whose automaton is too big, with the part responsible when it is ``X``."""
    m = next_depth(f)
    hint = (f"; it nests {m} X/WX operators inside F, G, U or R, so the automaton has to remember "
            f"the last {m} steps: about 2^{m} = {2 ** m:,} states" if m >= 8 else "")
    return (f"formula {_short(text)!r}: {what}{hint}. Simplify the formula (fewer nested operators, "
            "or spec.sequence for a long visiting order)")


# ----------------------------------------------------------------------------- letters

def letter_sets(aut, propositions) -> list:
    """Edges of a Spot automaton as ``[(src, dst, letters)]``, ``letters (2**k,)`` bool over ``propositions``."""
    d = aut.get_dict()
    bit = {}
    for p in aut.ap():
        if str(p) not in propositions:             # pragma: no cover - the formula's own propositions
            raise SpecificationError(f"automaton proposition {str(p)!r} is not one of {propositions}")
        bit[d.varnum(p)] = 1 << propositions.index(str(p))
    codes = np.arange(1 << len(propositions), dtype=np.int64)
    memo = {buddy.bddtrue.id(): np.ones(len(codes), bool), buddy.bddfalse.id(): np.zeros(len(codes), bool)}

    def holds(c):                                  # the letters the BDD ``c`` admits (Shannon expansion)
        if c.id() not in memo:
            on = (codes & bit[buddy.bdd_var(c)]) != 0
            memo[c.id()] = np.where(on, holds(buddy.bdd_high(c)), holds(buddy.bdd_low(c)))
        return memo[c.id()]

    return [(int(e.src), int(e.dst), holds(e.cond)) for e in aut.edges()]


def _translate(f: spot.formula, cap: int, *, deterministic: bool):
    opts = ("deterministic" if deterministic else "small", "sbacc", "buchi")
    return spot.translate(f, *opts, xargs=_SPOT_CAPS.format(n=cap))


def _check_nexts(text: str, f: spot.formula, limit: int) -> None:
    m = next_depth(f)
    if 2 ** m > limit:
        raise SpecificationError(too_big(text, f, f"its automaton needs more than {limit:,} states "
                                                  f"(at most {limit:,} are supported; refused before building it)"))


# ----------------------------------------------------------------------------- LTLf -> DFA

def dfa_from_formula(parsed, alphabet=None) -> DFA:
    """The minimal DFA of a :class:`~tubejax.analyses.spec.formula.ParsedFormula`, built by Spot.

    Parameters
    ----------
    parsed : ParsedFormula
    alphabet : ndarray of bool, shape (2**k,), optional
        Only these letters can occur (e.g. :func:`~tubejax.analyses.spec.labelling.map_alphabet`);
        the others lead to a rejecting sink, and the DFA is minimised over these letters.

    Returns
    -------
    DFA
        Over the formula's propositions (``parsed.propositions``).

    Raises
    ------
    SpecificationError
        More than :data:`MAX_PROPOSITIONS` propositions, more than about
        :data:`MAX_DFA_STATES` states foreseen from the nesting of ``X`` (refused before
        Spot runs), a determinisation Spot gives up at its caps, or a minimal DFA over
        :data:`MAX_DFA_STATES` states; the message gives the size and the part responsible.
    """
    k = len(parsed.propositions)
    if k > MAX_PROPOSITIONS:
        raise SpecificationError(f"formula {parsed.text!r} uses {k} propositions; at most "
                                 f"{MAX_PROPOSITIONS} are supported (2**k letters)")
    ok = np.ones(1 << k, bool) if alphabet is None else np.asarray(alphabet, bool)
    if ok.shape != (1 << k,):
        raise ValueError(f"alphabet: expected shape ({1 << k},), got {ok.shape}")
    f = spot_ltlf(parsed)
    _check_nexts(parsed.text, f, MAX_DFA_STATES)
    aut = _translate(spot.from_ltlf(f), 2 * MAX_DFA_STATES, deterministic=True)
    if not spot.is_deterministic(aut):
        raise SpecificationError(too_big(parsed.text, f, f"its deterministic automaton needs more than "
                                                         f"{2 * MAX_DFA_STATES:,} states (Spot stops there; at "
                                                         f"most {MAX_DFA_STATES:,} are supported)"))
    fin = spot.to_finite(aut)
    n = fin.num_states()
    delta = np.full((n + 1, 1 << k), n, np.int64)           # state n: the rejecting sink
    for src, dst, letters in letter_sets(fin, list(parsed.propositions)):
        delta[src, letters] = dst
    delta[:, ~ok] = n
    # Traces are never empty: a fresh initial state (row n + 1) reads the first letter as Spot's
    # does and accepts iff the empty trace satisfies the formula (the retired flloat's convention).
    delta = np.vstack([delta, delta[int(fin.get_init_state_number())]])
    acc = np.array([bool(fin.state_is_accepting(q)) for q in range(n)] + [False, _holds_on_empty(f)])
    d = minimise(DFA(parsed.propositions, parsed.labels, delta, n + 1, acc, parsed.text,
                     None if alphabet is None else ok))
    if d.n_states > MAX_DFA_STATES:
        raise SpecificationError(too_big(parsed.text, f, f"its minimal automaton has {d.n_states:,} states; "
                                                         f"at most {MAX_DFA_STATES:,} are supported"))
    return d


# ----------------------------------------------------------------------------- LTL -> Büchi

@dataclass(frozen=True, eq=False)
class Buchi:
    """A Büchi automaton with state-based acceptance over bit-mask letters (from Spot).

    Attributes
    ----------
    propositions : tuple of str
        Proposition of each letter bit, length ``k``.
    labels : tuple of str
        Region label of each proposition.
    post : list of list of int
        ``post[q][s]``: the successors of state ``q`` on letter ``s``, a bit set (Python int).
    initial : int
    accepting : ndarray of bool, shape (n_states,)
    deterministic : bool
    description : str
        The formula.
    formula : spot.formula
    """

    propositions: tuple
    labels: tuple
    post: list
    initial: int
    accepting: np.ndarray
    deterministic: bool
    description: str
    formula: object

    @property
    def n_states(self) -> int:
        return len(self.post)

    @property
    def accepting_bits(self) -> int:
        return sum(1 << q for q in np.flatnonzero(self.accepting).tolist())

    def step(self, states: int, letter: int) -> int:
        """Bit set of the successors of the bit set ``states`` on ``letter``."""
        out, q = 0, 0
        while states:
            if states & 1:
                out |= self.post[q][letter]
            states >>= 1
            q += 1
        return out


def buchi_from_formula(text: str, f: spot.formula, propositions, labels) -> Buchi:
    """Spot's Büchi automaton (state-based acceptance, deterministic where possible) of the LTL formula ``f``.

    Raises
    ------
    SpecificationError
        A nesting of ``X`` that needs more than :data:`MAX_BUCHI_STATES` states (before Spot
        runs), or an automaton with more states.
    """
    k = len(propositions)
    _check_nexts(text, f, MAX_BUCHI_STATES)
    aut = _translate(f, MAX_BUCHI_STATES, deterministic=True)
    if aut.num_states() > MAX_BUCHI_STATES:
        raise SpecificationError(too_big(text, f, f"its Büchi automaton has {aut.num_states():,} states; at "
                                                  f"most {MAX_BUCHI_STATES:,} are supported"))
    n = aut.num_states()
    post = [[0] * (1 << k) for _ in range(n)]
    for src, dst, letters in letter_sets(aut, list(propositions)):
        row = post[src]
        for s in np.flatnonzero(letters).tolist():
            row[s] |= 1 << dst
    acc = np.array([bool(aut.state_is_accepting(q)) for q in range(n)])
    return Buchi(tuple(propositions), tuple(labels), post, int(aut.get_init_state_number()), acc,
                 bool(spot.is_deterministic(aut)), text, f)
