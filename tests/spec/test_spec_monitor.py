"""Monitoring runs against the DFA (float64), and the closed loop of an avoid-and-order formula."""

import numpy as np

from tubejax.analyses.control import SimulationRuns, in_cells, plan_sequence
from tubejax.analyses.spec import (dfa_from_formula, monitor, parse_formula, plan_formula, region_letters,
                                   sequence_spec_plan, simulate_spec)

AVOID_AND_ORDER = "F(l3 & F(l2)) & G(!l4)"


def centre(d, label):
    return d.cells[d.cells_with_label(label)[0]].centroid


def test_letters_use_closed_regions(avoid_ts):
    d = avoid_ts.decomposition                      # cell (0,2) = [2,3] x [2,3] is region 4
    X = np.array([[2.5, 2.5], [2.0, 2.5], [2.0 - 1e-10, 2.5], [2.0 - 1e-8, 2.5], [0.5, 2.5], [1.0, 2.5]])
    assert region_letters(d, ["1", "4"], X).tolist() == [2, 2, 2, 0, 1, 1]
    # on the corner shared by region 1 (0,0) and nothing else: only 1
    assert region_letters(d, ["1", "4"], np.array([[1.0, 2.0]])).tolist() == [1]


def test_hand_made_trajectories(avoid_ts):
    d = avoid_ts.decomposition
    dfa = dfa_from_formula(parse_formula(AVOID_AND_ORDER, d.labels))
    s, t3, t2, t4, free = (centre(d, "1"), centre(d, "3"), centre(d, "2"), centre(d, "4"),
                           d.cells[9].centroid)
    X = np.array([[s, free, t3, free, t2],            # order kept, 4 avoided: satisfied
                  [s, t4, t3, free, t2],              # enters 4 at step 1
                  [s, free, t2, free, t3],            # wrong order: never satisfied, no entry
                  [s, t3, t2, t2, t4]])               # satisfied, then enters 4 at the end
    m = monitor(dfa, d, X)
    assert m.satisfied.tolist() == [True, False, False, False]
    assert m.avoided_entry.tolist() == [False, True, False, True]
    assert m.first_entry_time.tolist() == [-1, 1, -1, 4]
    assert m.first_dead_time.tolist() == [-1, 1, -1, 4]
    assert m.states.shape == (4, 5) and m.letters[1, 1] == dfa.letter(["4"])


def test_patrol_style_avoid_labels(avoid_ts):
    d = avoid_ts.decomposition
    dfa = dfa_from_formula(parse_formula("F(l2)", d.labels))
    X = np.array([[centre(d, "1"), centre(d, "4"), centre(d, "2")]])
    assert not monitor(dfa, d, X).avoided_entry[0]                  # "F l2" forbids nothing
    m = monitor(dfa, d, X, avoid=["4"])
    assert m.avoided_entry[0] and m.first_entry_time[0] == 1 and m.satisfied[0]


def test_2000_adversarial_runs_avoid_and_order(avoid_ts):
    """The issue's check: 2,000 adversarial runs of an avoid-and-order formula on a labelled map:
    0 entries into the avoided region, 100 % satisfaction (and no obstacle entry or tube exit)."""
    ts = avoid_ts
    sp = plan_formula(ts, 0, AVOID_AND_ORDER)
    sim = simulate_spec(ts, sp, SimulationRuns(n_runs=2000, mode="adversarial", seed=7))
    s = sim.summary()
    assert s["runs"] == 2000 and s["mode"] == "adversarial" and s["steps"] == sp.cost
    assert s["runs_satisfying_spec"] == 2000 and s["avoided_region_entries"] == 0
    assert s["obstacle_entries"] == 0 and s["tube_exits"] == 0 and s["workspace_exits"] == 0
    assert s["avoided_labels"] == ["4"] and s["spec"] == AVOID_AND_ORDER
    X = sim.trajectories
    assert X.dtype == np.float64
    # independent of the monitor: no state in the closed region 4, every run in 3 before it is in 2
    d = ts.decomposition
    assert not in_cells(d, X, 1e-9, d.cells_with_label("4")).any()
    in3, in2 = (in_cells(d, X, 1e-9, d.cells_with_label(l)) for l in ("3", "2"))
    first3 = np.argmax(in3, axis=1)
    assert in3.any(1).all() and all(in2[r, first3[r]:].any() for r in range(len(X)))


def test_the_plain_plan_is_caught_crossing_region_4(avoid_ts):
    """The cell-level plan to 2 runs over region 4: the monitor of "F l2 & G !l4" flags its runs."""
    ts = avoid_ts
    plain = sequence_spec_plan(ts, plan_sequence(ts, 0, ["2"]))
    dfa = dfa_from_formula(parse_formula("F(l2) & G(!l4)", ts.decomposition.labels))
    sim = simulate_spec(ts, plain, SimulationRuns(n_runs=200, mode="uniform", seed=1))
    assert sim.summary()["runs_satisfying_spec"] == 200          # its own spec (visit 2) holds
    m = monitor(dfa, ts.decomposition, sim.trajectories)
    assert m.avoided_entry.all() and not m.satisfied.any()


def test_sequence_plan_is_monitored(avoid_ts):
    sp = sequence_spec_plan(avoid_ts, plan_sequence(avoid_ts, 0, ["3", "2"]))
    assert sp.kind == "sequence" and sp.dfa.n_states == 3 and sp.spec == "1 -> 3 -> 2"
    assert sp.dfa.accepting[sp.states[-1]]
    s = simulate_spec(avoid_ts, sp, SimulationRuns(n_runs=100, mode="boundary", seed=2)).summary()
    assert s["runs_satisfying_spec"] == 100 and s["avoided_region_entries"] == 0
