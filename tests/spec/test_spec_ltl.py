"""LTL over infinite runs: Spot's Büchi automata, the sound product, the cheapest lasso, Spot-checked runs."""

import networkx as nx
import numpy as np
import pytest
import spot

import tubejax as tj
from tubejax.analyses.control import SimulationRuns, PlanningError
from tubejax.analyses.spec import (SpecificationError, lasso_words_satisfy, parse_ltl, patrol_formula, plan_ltl,
                                   plan_patrol, simulate_spec)
from tubejax.analyses.spec.automata import MAX_BUCHI_STATES
from tubejax.analyses.spec.lasso import direct_simulation
from tubejax.analyses.spec.automata import buchi_from_formula

from conftest import _abstraction

#: Eight cells round a wall: region 1 in the top-left corner, region 2 in the bottom-right one.
RING_MAP = "1..\n.#.\n..2\n"


@pytest.fixture(scope="module")
def ring_ts(tmp_path_factory):
    p = tmp_path_factory.mktemp("maps") / "ring.txt"
    p.write_text(RING_MAP)
    return _abstraction(p)


@pytest.fixture(scope="module")
def home_ts():
    """A 4 x 4 box grid: home box h (2 x 2 cells), b in the far corner, c between them below."""
    from tubejax.abstraction import build_abstraction
    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set
    from tubejax.model.workspace.boxgrid import box_grid
    d = box_grid([0, 0], [4, 4], [4, 4], labels={"h": ([0, 0], [2, 2]), "b": ([3, 3], [4, 4]), "c": ([2, 0], [3, 1])})
    return build_abstraction(d, LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2),
                                             W=Ball(2, 0.2)), L_max=10, progress=False)


def cell_graph(ts):
    G = nx.DiGraph()
    for e in ts.edges:
        if not G.has_edge(e.src, e.dst) or G[e.src][e.dst]["weight"] > e.L:
            G.add_edge(e.src, e.dst, weight=e.L)
    return G


def check_lasso(ts, sp):
    """The plan is the prefix then the cycle; consecutive cells are joined by the edges used."""
    pre, cyc = sp.lasso["prefix"], sp.lasso["cycle"]
    assert pre[-1] == cyc[0] == cyc[-1] and len(cyc) >= 2
    cycles = sp.stats["cycles"]
    assert sp.plan.cells == pre + cyc[1:] * cycles
    for k, (a, b) in zip(sp.plan.edges, zip(sp.plan.cells[:-1], sp.plan.cells[1:])):
        assert (ts.edges[k].src, ts.edges[k].dst) == (a, b)
    assert sp.plan.cost == sp.lasso["prefix_steps"] + cycles * sp.lasso["cycle_steps"]


def test_ring_cheapest_surveillance_cycle_is_hand_derived(ring_ts):
    """GF l1 & GF l2 on the ring: the corners are 14 steps apart either way round (two 7-step
    jumps 0 -> 2 -> 7, or 0 -> 5 -> 7; the four 4-step edges along a side cost 16), so the
    cheapest cycle is 28 steps from the start corner, with no prefix. networkx agrees."""
    ts = ring_ts
    assert ts.decomposition.labels[0] == "1" and ts.decomposition.labels[7] == "2"
    sp = plan_ltl(ts, 0, "GF l1 & GF l2", cycles=3)
    check_lasso(ts, sp)
    assert (sp.lasso["prefix_steps"], sp.lasso["cycle_steps"]) == (0, 28)
    d = dict(nx.all_pairs_dijkstra_path_length(cell_graph(ts)))
    assert sp.lasso["cycle_steps"] == d[0][7] + d[7][0] == 28
    assert {0, 7} <= set(sp.lasso["cycle"])
    assert sp.kind == "ltl" and sp.stats["buchi_deterministic"]


def test_ring_start_elsewhere_pays_a_prefix(ring_ts):
    sp = plan_ltl(ring_ts, 3, "GF l1 & GF l2")
    check_lasso(ring_ts, sp)
    # the cheapest cycles (0 -> 2 -> 7 -> 5 -> 0 and back) skip cell 3; cells 0 and 5 are 4 steps away
    assert sp.lasso["cycle_steps"] == 28 and sp.lasso["prefix_steps"] == 4
    assert sp.lasso["prefix"] in ([3, 0], [3, 5])
    sp = plan_ltl(ring_ts, 1, "G F l2")
    assert sp.lasso["cycle_steps"] == min(
        w + nx.dijkstra_path_length(cell_graph(ring_ts), b, 7) for b, w in
        [(e.dst, e.L) for e in ring_ts.edges if e.src == 7])


def test_reach_and_stay_needs_a_self_sustaining_cycle(ring_ts, home_ts):
    """On the ring region 1 is one cell and no edge stays in it: FG l1 is unrealisable. A 2 x 2
    label box h is one convex piece, so tubes between its cells stay in it: FG lh is planned,
    its cycle inside h, and adversarial runs checked by Spot satisfy it."""
    with pytest.raises(PlanningError, match=r"region 1 has no self-sustaining cycle: no cycle of transitions "
                                            r"reachable from cell 0 stays in it"):
        plan_ltl(ring_ts, 0, "FG l1")
    ts = home_ts
    sp = plan_ltl(ts, 15, "F G lh & G !lc & G(lb -> F lh)", cycles=2)
    check_lasso(ts, sp)
    assert all(ts.decomposition.labels[c] == "h" for c in sp.lasso["cycle"])
    assert not sp.stats["buchi_deterministic"]              # FG a has no deterministic Büchi automaton
    s = simulate_spec(ts, sp, SimulationRuns(n_runs=40, mode="adversarial", seed=5)).summary()
    assert s["runs_satisfying_spec"] == 40 and s["avoided_region_entries"] == 0


def test_unrealisable_formulas_are_explained(avoid_ts, blocked_ts):
    with pytest.raises(PlanningError, match=r"'G F l6' cannot be met with 'G !l4' kept: every path from "
                                            r"cell 0 to region 6 crosses region\(s\) 4"):
        plan_ltl(blocked_ts, 0, "GF l6 & G !l4")
    with pytest.raises(PlanningError, match="no infinite run satisfies 'GF l1 & G !l1' at all"):
        plan_ltl(avoid_ts, 0, "GF l1 & G !l1")
    with pytest.raises(PlanningError, match="the start cell 0 already violates it"):
        plan_ltl(avoid_ts, 0, "G !l1 & GF l2")


def test_bad_formulas_are_refused_with_the_right_words(avoid_ts):
    labels = avoid_ts.decomposition.labels
    with pytest.raises(SpecificationError, match=r"syntax error at position 7: unexpected closing parenthesis"):
        parse_ltl("F(l3 & ) & G l4", labels)
    with pytest.raises(SpecificationError, match=r"unknown propositions l9 \(position 3\): no region carries "
                                                 r"these labels \(the map's propositions: l1, l2, l3, l4\)"):
        parse_ltl("GF l9", labels)
    with pytest.raises(SpecificationError, match=r"'last' \(position 7\) only exist in LTLf formulas .* give "
                                                 r"this formula as spec.formula"):
        parse_ltl("F l3 & last", labels)
    with pytest.raises(SpecificationError, match=r"'GF' .* belong to LTL over infinite runs: give the formula "
                                                 r"as spec.ltl"):
        tj.plan(avoid_ts, "GF l3 & GF l2", start=0)
    with pytest.raises(SpecificationError, match=r"needs more than 512 states .* about 2\^10 = 1,024 states"):
        plan_ltl(avoid_ts, 0, "G(l3 -> " + "X " * 10 + "l2)")
    assert MAX_BUCHI_STATES == 512
    assert parse_ltl("GF l3 & FG l2", labels).formula == spot.formula("G F l3 & F G l2")


def test_patrol_is_the_sequenced_patrolling_formula(avoid_ts):
    """spec.patrol [3, 2] avoiding 4 is G F(l3 & F(l2)) & G !l4 with the cycle anchored in region 3:
    the same cycle steps as the free lasso, whose prefix may be shorter (it joins the cycle anywhere)."""
    for labels, avoid in [(["3", "2"], ["4"]), (["2", "3"], []), (["3"], [])]:
        patrol = plan_patrol(avoid_ts, 0, labels, cycles=2, avoid=avoid)
        free = plan_ltl(avoid_ts, 0, patrol_formula(labels, avoid), cycles=2)
        assert free.lasso["cycle_steps"] == patrol.stats["cycle_steps"], labels
        assert free.lasso["prefix_steps"] <= patrol.stats["prefix_steps"]
        assert avoid_ts.decomposition.labels[patrol.stats["anchor"]] == labels[0]
    assert patrol_formula(["3", "5", "6"], ["4"]) == "G F(l3 & F(l5 & F(l6))) & G !l4"


PATTERNS = {
    "surveillance": "GF l3 & GF l2 & G !l4",
    "response": "G(l3 -> F l2) & GF l3",
    "sequenced patrolling": "G F(l3 & F(l2 & F l1))",
    "avoidance": "G !l4 & GF l3 & F l2",
}


@pytest.mark.parametrize("name", sorted(PATTERNS))
def test_simulated_runs_satisfy_the_formula_by_spot(avoid_ts, name):
    """Adversarial runs of each pattern's lasso; every run's ultimately periodic words checked by Spot."""
    sp = plan_ltl(avoid_ts, 0, PATTERNS[name], cycles=2)
    check_lasso(avoid_ts, sp)
    s = simulate_spec(avoid_ts, sp, SimulationRuns(n_runs=40, mode="adversarial", seed=3)).summary()
    assert s["runs_satisfying_spec"] == 40 and s["tube_exits"] == 0 and s["obstacle_entries"] == 0
    assert s["avoided_region_entries"] == 0
    assert s["lasso"]["prefix"] == sp.lasso["prefix"] and s["lasso"]["cycle"] == sp.lasso["cycle"]


def test_word_check_finds_violations():
    """A negative control for the Spot word check: cycles without region 2 violate GF l2."""
    f = spot.formula("GF l2 & G !l4")
    props = ("l2", "l4")
    good = np.array([[0, 0, 0, 1, 0, 1, 0]])                       # prefix 2 steps, cycle 2 x 2 steps
    assert lasso_words_satisfy(f, props, good, 2, 2, 2).tolist() == [True]
    bad_cycle = np.array([[0, 0, 0, 1, 0, 0, 0]])                  # the second turn never meets 2
    touches_4 = np.array([[0, 2, 0, 1, 0, 1, 0]])
    assert lasso_words_satisfy(f, props, np.vstack([bad_cycle, touches_4]), 2, 2, 2).tolist() == [False, False]


def test_direct_simulation_is_a_simulation():
    """Every pair the relation holds for: acceptance and every move are matched (checked directly)."""
    for text in ["GF l1 & GF l2", "G(l1 -> F l2)", "FG l1 | GF l2"]:
        p = parse_ltl(text, ["1", "2"])
        b = buchi_from_formula(text, p.formula, p.propositions, p.labels)
        down = direct_simulation(b, np.ones(1 << len(p.propositions), bool))
        n = b.n_states
        for r in range(n):
            assert down[r] >> r & 1                                  # reflexive
            for m in range(n):
                if down[r] >> m & 1:
                    assert b.accepting[r] or not b.accepting[m]
                    for s in range(1 << len(p.propositions)):
                        for m2 in range(n):
                            if b.post[m][s] >> m2 & 1:
                                assert any(b.post[r][s] >> r2 & 1 and down[r2] >> m2 & 1 for r2 in range(n))


def test_api_and_settings(avoid_ts):
    sp = tj.plan(avoid_ts, ltl="GF l3 & GF l2 & G !l4", start=0, cycles=2)
    assert sp.kind == "ltl" and sp.avoid == ("4",) and sp.stats["cycles"] == 2
    with pytest.raises(tj.InputError, match="give exactly one of spec"):
        tj.plan(avoid_ts, "F l3", ltl="GF l3", start=0)
    from tubejax.inputs import SpecSettings, validate_section
    s = validate_section(SpecSettings, {"sequence": [1, 3], "ltl": "GF l3"}, "spec")
    assert s.ltl == "GF l3"
    with pytest.raises(tj.InputError, match="give one of spec.formula, spec.ltl and spec.patrol"):
        validate_section(SpecSettings, {"sequence": [1, 3], "ltl": "GF l3", "formula": "F l3"}, "spec")
