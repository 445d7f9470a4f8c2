"""Formulas that cannot be met: the message names the part that fails and says why, in words.

Avoid map (conftest): top row ``1 . 4 . 2`` above a wall, bottom row ``3 . . . .``; cell 0 is
region 1, cell 7 region 3. Every transition from cell 0 takes at least 2 steps.
"""

import pytest

from tubejax.analyses.control.planner import PlanningError
from tubejax.analyses.spec import plan_formula
from tubejax.analyses.spec.formula import describe
from tubejax.analyses.spec.formula import parse_formula


def why(ts, start, formula):
    with pytest.raises(PlanningError) as e:
        plan_formula(ts, start, formula)
    msg = str(e.value)
    assert msg.startswith(f"no plan satisfies {formula!r}: ")
    return msg.split(": ", 1)[1]


def test_false_says_it_never_holds(avoid_ts):
    assert why(avoid_ts, 0, "false") == "it is 'false', which never holds: no run satisfies it"
    assert why(avoid_ts, 0, "F l2 & false") == "its part 'false' is 'false', which never holds: no run satisfies it"


def test_contradicting_parts_are_named_with_what_each_asks(avoid_ts):
    assert why(avoid_ts, 0, "F l3 & G !l3") == (
        "parts 'F(l3)' and 'G(!(l3))' contradict each other: 'F(l3)' asks the state to be in region 3 at "
        "some instant, and 'G(!(l3))' asks it never to be in region 3; no run can do both: the formula "
        "is unsatisfiable")
    msg = why(avoid_ts, 0, "F(l4 & X(false))")
    assert "unsatisfiable in itself" in msg


def test_regions_that_never_meet(avoid_ts):
    msg = why(avoid_ts, 0, "F(l3 & l2) & G !l4")
    assert msg.startswith("part 'F((l3 & l2))' asks the state to be in region 3 and in region 2 at some instant")
    assert "(regions 2, 3 at once)" in msg and "unsatisfiable on this map" in msg


def test_violated_at_the_start_cell(avoid_ts):
    assert why(avoid_ts, 0, "G !l1") == (
        "it is already violated at the start cell 0: it asks the state never to be in region 1, and the "
        "start cell lies in region 1")
    assert why(avoid_ts, 0, "l3") == (
        "it is already violated at the start cell 0: it asks the state to start in region 3, and the "
        "start cell lies outside region 3")
    assert why(avoid_ts, 0, "F l2 & G(!l1)").startswith(
        "part 'G(!(l1))' is already violated at the start cell 0: 'G(!(l1))' asks the state never to be in region 1")


def test_next_at_a_step_no_tube_is_surely_there(avoid_ts):
    msg = why(avoid_ts, 0, "X l3")
    assert msg.startswith("'X(l3)' cannot be met from cell 0: it asks the state to be in region 3 at time step 1 "
                          "(1 step after the start); region 3 can be reached from cell 0, but not at the time "
                          "step it fixes")
    Ls = sorted({e.L for e in avoid_ts.edges if e.src == 0})
    assert f"the transitions from cell 0 take {Ls[0]} to {Ls[-1]} steps" in msg and Ls[0] > 1
    msg = why(avoid_ts, 0, "G(!l4) & F(l2) & X l3")
    assert msg.startswith("part 'X(l3)' cannot be met on its own from cell 0: it asks the state to be in region 3 "
                          "at time step 1")


def test_unreachable_while_kept(avoid_ts, blocked_ts):
    assert why(avoid_ts, 0, "F l2 & G !l4 & G(!l3)") == (
        "its parts can each be met, and every two of them together, but not all at once: with 'G(!(l4))' and "
        "'G(!(l3))' kept, region 2 cannot be reached from cell 0 (every path there enters, or has a tube that "
        "may sweep, a region it forbids)")
    assert why(blocked_ts, 0, "!l4 U l6") == (
        "'(!(l4) U l6)' cannot be met from cell 0: it asks the state to stay outside region 4 until it is in "
        "region 6, but region 6 cannot be reached from cell 0 while keeping to it (every path there enters, or "
        "has a tube that may sweep, a region it forbids)")


def test_describe_common_shapes():
    p = parse_formula("F l3", ["3", "4"])
    cases = {"F(l3)": "the state to be in region 3 at some instant",
             "G(!l4)": "the state never to be in region 4",
             "G(l3 | l4)": "the state to be in region 3 or in region 4 at every instant",
             "X X WX(!l4)": "the state to be outside region 4 at time step 3 (3 steps after the start), if the run "
                            "lasts that long",
             "l3 U l4": "the state to stay in region 3 until it is in region 4",
             "X last": "the run to end exactly at time step 1",
             "G(l3 -> X l4)": "that 'G((l3 -> X(l4)))' holds"}
    for text, words in cases.items():
        q = parse_formula(text, ["3", "4"])
        assert describe(q, q.ltlf) == words, text
    assert p.propositions == ("l3",)
