"""Hostile formulas: deep nesting and exponential automata are refused up front, with numbers."""

import re
import time

import numpy as np
import pytest

from tubejax.errors import InputError
from tubejax.analyses.spec import SpecificationError, dfa_from_formula, parse_formula, plan_formula, sequence_dfa
from tubejax.analyses.spec.formula import MAX_NESTING
from tubejax.analyses.spec.product import MAX_PRODUCT_PAIRS, build_product

LABELS = ["3", "5"]


@pytest.mark.parametrize("text", ["!" * 1500 + "l3", "(" * 1500 + "l3" + ")" * 1500,
                                  "F(l3 & " * 1500 + "l5" + ")" * 1500, "X " * 1500 + "l3"])
def test_deep_nesting_is_refused_with_its_depth(text):
    with pytest.raises(SpecificationError, match=rf"nested \d+ deep .*at most {MAX_NESTING} are supported") as e:
        parse_formula(text, LABELS)
    assert isinstance(e.value, InputError)
    depth = int(re.search(r"nested (\d+) deep", str(e.value)).group(1))
    assert depth == (4500 if text.startswith("F(") else 1500)
    assert len(str(e.value)) < 300                      # the formula is shortened in the message


def test_nesting_depth_is_counted_by_hand():
    """``F(l3 & F(l5))``: F, (, &, F, ( = 5; the limit is inclusive."""
    ok = "X " * MAX_NESTING + "l3"
    assert parse_formula(ok, LABELS).propositions == ("l3",)
    with pytest.raises(SpecificationError, match=rf"nested {MAX_NESTING + 1} deep"):
        parse_formula("X " + ok, LABELS)
    inner = "F(l3 & F(l5))"
    with pytest.raises(SpecificationError, match=rf"nested {MAX_NESTING + 1} deep"):
        parse_formula("!" * (MAX_NESTING - 4) + inner, LABELS)
    assert parse_formula("!" * (MAX_NESTING - 5) + inner, LABELS)
    twelve = "".join(f"F(l{c} & " for c in "123456789ab") + "F(lc)" + ")" * 11
    assert parse_formula(twelve, list("123456789abc"))   # depth 35: a 12-region sequence


@pytest.mark.parametrize("n", [12, 16, 28])
def test_exponential_automaton_is_refused_before_memory_grows(n):
    """``F(l3 & X^n l5)`` remembers the last n steps: 2^n states. Refused from the formula alone,
    before Spot runs, with the limit and the likely size."""
    p = parse_formula("F(l3 & " + "X " * n + "l5)", LABELS)
    t = time.perf_counter()
    with pytest.raises(SpecificationError) as e:
        dfa_from_formula(p)
    assert time.perf_counter() - t < 2                     # refused from the formula: no automaton is built
    msg = str(e.value)
    assert "its automaton needs more than 2,048 states" in msg and "refused before building it" in msg
    assert f"2^{n} = {2 ** n:,} states" in msg


def test_state_limit_is_exact():
    """X^10: 1,025 states (built); X^11: 2,049 minimal states, one more than the limit."""
    assert dfa_from_formula(parse_formula("F(l3 & " + "X " * 10 + "l5)", LABELS)).n_states == 1025
    with pytest.raises(SpecificationError, match="its minimal automaton has 2,049 states; at most 2,048"):
        dfa_from_formula(parse_formula("F(l3 & " + "X " * 11 + "l5)", LABELS))


def test_alternating_operators_are_cheap_for_spot():
    """Alternating F/G blew up the retired construction's obligation sets (it needed a work
    budget); Spot simplifies them: F G F G ... l3 is 'l3 at the last instant'."""
    t = time.perf_counter()
    d = dfa_from_formula(parse_formula("F G " * 8 + "l3", LABELS))
    assert time.perf_counter() - t < 5
    assert d.accepts(np.array([[0, 1], [1, 0]])).tolist() == [True, False]


def test_readme_formulas_are_far_below_the_limits(paper_ts):
    for f in ["F(l3 & F(l5 & F l6)) & G(!l4)", "F(l3 & F(l4 & F(l5 & F(l6))))"]:
        sp = plan_formula(paper_ts, 0, f)
        assert sp.dfa.n_states <= 10


def test_product_size_is_checked_before_it_is_built(avoid_ts, monkeypatch):
    import tubejax.analyses.spec.product as product
    d = dfa_from_formula(parse_formula("F(l3 & X X X l2)", ["2", "3"]))
    monkeypatch.setattr(product, "MAX_PRODUCT_PAIRS", avoid_ts.n_edges * d.n_states - 1)
    with pytest.raises(SpecificationError, match=rf"has {avoid_ts.n_edges * d.n_states:,} \(edge, state\) pairs"):
        build_product(avoid_ts, d)
    assert MAX_PRODUCT_PAIRS >= 10_000_000


def test_long_patrol_automaton_is_built_and_analysed_in_linear_time():
    """spec.patrol=[1,3] sim.cycles=10000: 20,001 states (quadratic before: about 20 s)."""
    t = time.perf_counter()
    d = sequence_dfa(["1", "3"] * 10_000)
    live, reach = d.live(), d.reachable()
    assert time.perf_counter() - t < 5
    assert d.delta[0].tolist() == [0, 1, 0, 20_000]            # letters {}, {1}, {3}, {1, 3}
    assert live.all() and reach.all() and d.n_states == 20_001
    small = sequence_dfa(["1", "2"])
    sink = np.zeros((1, small.n_letters), np.int64) + small.n_states
    from tubejax.analyses.spec.dfa import DFA
    dead = DFA(small.propositions, small.labels, np.vstack([small.delta, sink]), 0,
               np.append(small.accepting, False))
    assert dead.live().tolist() == [True, True, True, False]
    assert dead.reachable().tolist() == [True, True, True, False]


def test_messages_stay_short_for_long_formulas():
    with pytest.raises(SpecificationError) as e:
        parse_formula("x3 " * 5000 + "l7 " * 5000, LABELS)
    msg = str(e.value)
    assert len(msg) < 2500 and "4990 more" in msg and "unknown propositions l7 (position 15000)" in msg
