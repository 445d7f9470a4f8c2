"""DFAs: checked against the LTLf trace semantics (an oracle in this file) and the retired flloat sizes."""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tubejax.analyses.spec import dfa_from_formula, parse_formula, sequence_dfa
from tubejax.analyses.spec.dfa import DFA
from tubejax.analyses.spec.formula import sequence_formula

LABELS = ["1", "2", "3"]


def truth(f, trace, i=0):
    """LTLf semantics of a formula tree on a finite trace of letters (sets of internal names), from
    the definitions (an independent oracle: no automaton). ``a U b U c`` is ``a U (b U c)``."""
    n = len(trace)
    t = type(f).__name__
    if t == "LTLfTrue":
        return True
    if t == "LTLfFalse":
        return False
    if t == "LTLfAtomic":
        return f.s in trace[i]
    if t == "LTLfLast":
        return i == n - 1
    if t == "LTLfNot":
        return not truth(f.f, trace, i)
    if t == "LTLfAnd":
        return all(truth(g, trace, i) for g in f.formulas)
    if t == "LTLfOr":
        return any(truth(g, trace, i) for g in f.formulas)
    if t == "LTLfImplies":
        v = truth(f.formulas[0], trace, i)
        for g in f.formulas[1:]:
            v = (not v) or truth(g, trace, i)
        return v
    if t == "LTLfEquivalence":
        vs = [truth(g, trace, i) for g in f.formulas]
        return all(vs) or not any(vs)
    if t == "LTLfNext":
        return i + 1 < n and truth(f.f, trace, i + 1)
    if t == "LTLfWeakNext":
        return i + 1 >= n or truth(f.f, trace, i + 1)
    if t == "LTLfEventually":
        return any(truth(f.f, trace, j) for j in range(i, n))
    if t == "LTLfAlways":
        return all(truth(f.f, trace, j) for j in range(i, n))
    a, rest = f.formulas[0], f.formulas[1:]
    b = rest[0] if len(rest) == 1 else type(f)(rest)
    if t == "LTLfUntil":
        return any(truth(b, trace, j) and all(truth(a, trace, k) for k in range(i, j)) for j in range(i, n))
    assert t == "LTLfRelease"
    return all(truth(b, trace, j) or any(truth(a, trace, k) for k in range(i, j)) for j in range(i, n))


def interp(letter, k):
    return [{f"p{b}" for b in range(k) if s >> b & 1} for s in letter]


@pytest.mark.parametrize("text, states", [("F(l2) & G(!l1)", 3), ("l1 U l2", 3), ("G(l1 -> X l2)", 3),
                                          ("F(l1 & F l2)", 3), ("WX(l1) | last", 4), ("G(F(l1))", 2),
                                          ("!(l1 R l2)", 3)])
def test_minimal_sizes_of_the_retired_flloat_automata(text, states):
    """The minimal DFA sizes flloat's own (sympy-based) to_automaton gave, recorded before flloat was
    retired; Spot's route plus Moore gives the same minimal automata."""
    assert dfa_from_formula(parse_formula(text, LABELS)).n_states == states


def formulas(depth):
    atoms = st.sampled_from(["l1", "l2", "l3", "true", "false", "last"])
    if depth == 0:
        return atoms
    sub = formulas(depth - 1)
    return st.one_of(
        atoms,
        st.builds(lambda o, a: f"{o}({a})", st.sampled_from(["!", "X", "WX", "F", "G"]), sub),
        st.builds(lambda a, o, b: f"({a} {o} {b})", sub, st.sampled_from(["&", "|", "->", "<->", "U", "R"]), sub))


@settings(max_examples=60, deadline=None)
@given(formulas(3), st.lists(st.lists(st.integers(0, 7), min_size=1, max_size=7), min_size=1, max_size=12))
def test_accepts_exactly_the_traces_that_are_models(text, traces):
    p = parse_formula(text, LABELS) if any(f"l{i}" in text for i in "123") else None
    if p is None:                                 # no proposition: add one so the alphabet is not empty
        text = f"({text}) & (l1 | !l1)"
        p = parse_formula(text, LABELS)
    d = dfa_from_formula(p)
    k = len(p.propositions)
    for tr in traces:
        letters = [s & ((1 << k) - 1) for s in tr]
        assert bool(d.accepts(np.array(letters))) == truth(p.ltlf, interp(letters, k)), text


@pytest.mark.parametrize("text", ["l1 -> l2 -> l3", "l1 <-> l2 <-> l3", "l1 U l2 U l3", "l1 R l2 R l3",
                                  "l1 & l2 U l3 | X l1", "!l1 U l2 & G F l3"])
def test_chains_and_precedence_on_every_short_trace(text):
    p = parse_formula(text, LABELS)
    d = dfa_from_formula(p)
    for n in range(1, 4):
        for word in itertools.product(range(8), repeat=n):
            assert bool(d.accepts(np.array(word))) == truth(p.ltlf, interp(word, 3)), (text, word)


def equivalent(a: DFA, b: DFA, length=5):
    """Same answer on every word up to ``length`` (vectorised over all words of each length)."""
    assert a.n_letters == b.n_letters
    for n in range(1, length + 1):
        words = np.array(list(itertools.product(range(a.n_letters), repeat=n)))
        if not np.array_equal(a.accepts(words), b.accepts(words)):
            return False
    return True


@pytest.mark.parametrize("seq", [["1"], ["1", "2"], ["2", "1", "2"], ["1", "2", "3"], ["3", "3", "1"]])
def test_sequence_dfa_is_the_formula_automaton(seq):
    direct = sequence_dfa(seq)
    labels = sorted(set(seq))
    via = dfa_from_formula(parse_formula(sequence_formula([f"l{l}" for l in seq]), labels))
    assert direct.labels == via.labels == tuple(labels)
    assert direct.n_states == len(seq) + 1
    # the minimal automaton is smaller when a label repeats at once (3, 3: one instant visits both)
    assert via.n_states == len(seq) + 1 - sum(a == b for a, b in zip(seq, seq[1:]))
    assert equivalent(direct, via)


def test_live_inclusion_and_letters():
    d = dfa_from_formula(parse_formula("F(l2) & G(!l1)", LABELS))
    assert d.propositions == ("l1", "l2")
    dead = int(d.delta[d.initial, d.letter(["1"])])
    done = int(d.delta[d.initial, d.letter(["2"])])
    assert d.accepting[done] and not d.live()[dead] and d.live()[d.initial]
    inc = d.inclusion()
    assert inc[dead].all()                                    # the empty language is in every language
    assert inc[d.initial, done] and not inc[done, d.initial]  # what 0 accepts, 'done' accepts too
    assert d.letter(["1", "2", "3"]) == 3 and d.letter([]) == 0
    chain = sequence_dfa(["1", "2", "3"])
    inc = chain.inclusion()
    assert all(inc[k, k + 1] and not inc[k + 1, k] for k in range(3))
    assert np.array_equal(chain.run(np.array([[0, 1, 4, 2, 4]])), [[0, 1, 1, 2, 3]])


def test_boundary_letter_visits_two_targets_at_once():
    chain = sequence_dfa(["1", "2"])
    assert chain.delta[0, chain.letter(["1", "2"])] == 2       # as in LTLf: F(l1 & F l2) holds at once


def test_unsatisfiable_formula_has_no_live_state():
    d = dfa_from_formula(parse_formula("F(l1) & G(!l1)", LABELS))
    assert not d.live()[d.initial] and not d.accepting.any()
