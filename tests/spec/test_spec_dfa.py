"""DFAs: checked against flloat's own automaton and against flloat's trace semantics."""

import itertools

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tubejax.analyses.spec import dfa_from_formula, parse_formula, sequence_dfa
from tubejax.analyses.spec.dfa import DFA
from tubejax.analyses.spec.formula import sequence_formula

LABELS = ["1", "2", "3"]


def interp(letter, k):
    return {f"p{b}": True for b in range(k) if letter >> b & 1}


@pytest.mark.parametrize("text", ["F(l2) & G(!l1)", "l1 U l2", "G(l1 -> X l2)", "F(l1 & F l2)",
                                  "WX(l1) | last", "G(F(l1))", "!(l1 R l2)"])
def test_isomorphic_to_flloats_own_automaton(text):
    """flloat's to_automaton (sympy-based, minimal) and ours accept the same language: both are
    minimal, so they must be isomorphic; walk both from the initial states."""
    p = parse_formula(text, LABELS)
    ours = dfa_from_formula(p)
    ref = p.ltlf.to_automaton()
    k = len(p.propositions)
    assert len(ref.states) == ours.n_states
    pair = {ours.initial: ref.initial_state}
    todo = [ours.initial]
    while todo:
        q = todo.pop()
        r = pair[q]
        assert bool(ours.accepting[q]) == (r in ref.accepting_states)
        for s in range(1 << k):
            q2, r2 = int(ours.delta[q, s]), ref.get_successor(r, interp(s, k))
            if q2 in pair:
                assert pair[q2] == r2
            else:
                pair[q2] = r2
                todo.append(q2)
    assert len(set(pair.values())) == len(pair) == ours.n_states


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
def test_accepts_exactly_the_traces_flloat_says_are_models(text, traces):
    p = parse_formula(text, LABELS) if any(f"l{i}" in text for i in "123") else None
    if p is None:                                 # no proposition: add one so the alphabet is not empty
        text = f"({text}) & (l1 | !l1)"
        p = parse_formula(text, LABELS)
    d = dfa_from_formula(p)
    k = len(p.propositions)
    for tr in traces:
        letters = [s & ((1 << k) - 1) for s in tr]
        assert bool(d.accepts(np.array(letters))) == p.ltlf.truth([interp(s, k) for s in letters], 0), text


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
