"""The sound product: detours, refused tubes, unsatisfiable formulas, sequences as a special case."""

import itertools

import networkx as nx
import numpy as np
import pytest

from tubejax.analyses.control import SimulationRuns, PlanningError, plan_sequence
from tubejax.model.geometry import Polytope
from tubejax.model.geometry.obstacles import to_shapely
from tubejax.analyses.spec import (EdgeLetters, build_product, cell_letters, dfa_from_formula, edge_letters,
                                   parse_formula, plan_dfa, plan_formula, plan_sequence_spec, sequence_dfa)


def tube_sets(ts, k):
    e = ts.edges[k]
    q = ts.tubes[k].vertices(ts.Z[e.src], ts.decomposition.cells[e.src])
    return [to_shapely(Polytope.from_vertices(q[l])) for l in range(1, e.L + 1)]


def meets_region(ts, k, label):
    """Independent check (shapely): does any tube set of edge k touch a closed cell of ``label``?"""
    cells = [to_shapely(ts.decomposition.cells[c]) for c in ts.decomposition.cells_with_label(label)]
    return any(P.intersects(Q) for Q in tube_sets(ts, k) for P in cells)


def random_letters_accepted(ts, sp, draws=200, seed=0):
    """Every letter sequence the tubes allow along the plan (sampled) is accepted by the DFA."""
    rng = np.random.default_rng(seed)
    dfa = sp.dfa
    must0, may0 = cell_letters(ts.decomposition, dfa.labels, sp.plan.cells[0])
    lt = edge_letters(ts, dfa.labels, sp.plan.edges)
    must = [must0] + [int(m) for r, k in enumerate(sp.plan.edges) for m in lt.must[r, :ts.edges[k].L]]
    may = [may0] + [int(m) for r, k in enumerate(sp.plan.edges) for m in lt.may[r, :ts.edges[k].L]]
    for _ in range(draws):
        word = [a | (b & ~a & int(rng.integers(0, dfa.n_letters))) for a, b in zip(must, may)]
        assert dfa.accepts(np.array(word)), word
    return len(must)


def test_detour_around_an_avoided_region(avoid_ts):
    ts = avoid_ts
    plain = plan_sequence(ts, 0, ["2"])
    assert any(meets_region(ts, k, "4") for k in plain.edges)         # the plain plan crosses 4
    sp = plan_formula(ts, 0, "F(l2) & G(!l4)")
    assert sp.plan.cells[0] == 0 and ts.decomposition.labels[sp.plan.cells[-1]] == "2"
    assert not any(meets_region(ts, k, "4") for k in sp.plan.edges)
    assert sp.cost > plain.cost and sp.avoid == ("4",)
    # independent optimum: Dijkstra (networkx) over the edges whose tubes never touch region 4
    G = nx.DiGraph()
    for k, e in enumerate(ts.edges):
        if not meets_region(ts, k, "4"):
            if not G.has_edge(e.src, e.dst) or G[e.src][e.dst]["weight"] > e.L:
                G.add_edge(e.src, e.dst, weight=e.L)
    best = min(nx.shortest_path_length(G, 0, c, weight="weight")
               for c in ts.decomposition.cells_with_label("2") if c in G)
    assert sp.cost == best
    assert random_letters_accepted(ts, sp) == sp.cost + 1


def test_refuses_an_edge_whose_tube_crosses_the_avoided_region(avoid_ts):
    ts = avoid_ts
    k = ts.edge_index()[1, 4]                           # used by the plain plan 0 -> 1 -> 4
    assert k in plan_sequence(ts, 0, ["2"]).edges
    dfa = dfa_from_formula(parse_formula("F(l2) & G(!l4)", ts.decomposition.labels))
    prod = build_product(ts, dfa)
    live = dfa.live()
    assert all(prod.succ[k, q] < 0 or not live[prod.succ[k, q]] for q in np.flatnonzero(live))
    assert not any(e == k for e in prod.arc_edge.values())


def test_refuses_a_tube_that_only_may_sweep_the_region(paper_ts):
    """Edge (7,9) -> (8,8) on the paper map never surely enters region 5, but its tube touches it."""
    ts = paper_ts
    k = ts.edge_index()[52, 56]
    dfa = dfa_from_formula(parse_formula("F(l6) & G(!l5)", ts.decomposition.labels))
    prod = build_product(ts, dfa)
    assert not any(e == k for e in prod.arc_edge.values())
    free = build_product(ts, dfa_from_formula(parse_formula("F(l6) & G(!l4)", ts.decomposition.labels)))
    assert any(e == k for e in free.arc_edge.values())          # without "never 5" it is used


def test_unsatisfiable_formula_names_the_parts(blocked_ts):
    ts = blocked_ts
    assert plan_formula(ts, 0, "F(l6)").cost > 0
    with pytest.raises(PlanningError) as e:
        plan_formula(ts, 0, "F(l6) & G(!l4)")
    msg = str(e.value)
    assert "no plan satisfies 'F(l6) & G(!l4)'" in msg
    assert "part 'F(l6)' cannot be met together with 'G(!(l4))'" in msg
    assert "region 6 cannot be reached from cell 0" in msg
    with pytest.raises(PlanningError, match=r"part 'F\(l6\)' cannot be met together with 'G\(!\(l4\)\)'"):
        plan_formula(ts, 0, "G(!l4) & F(l1) & F(l6)")
    with pytest.raises(PlanningError, match="unsatisfiable"):
        plan_formula(ts, 0, "F(l4 & X(false))")
    with pytest.raises(PlanningError, match=r"already violated at the start cell 0"):
        plan_formula(ts, 0, "G(!l1)")
    with pytest.raises(PlanningError, match=r"part 'G\(!\(l4\)\)' may already be violated at the start cell 1: "
                                            r".* the start cell meets region 4"):
        plan_formula(ts, 1, "G(!l4) & F(l6)")
    with pytest.raises(PlanningError, match="not a cell id"):
        plan_formula(ts, 9, "F(l6)")


SEQUENCES = [list(p) for p in itertools.permutations("23456", 2)] + [["3", "4", "5", "6"], ["6", "2", "4"]]


def test_sequences_are_a_special_case(paper_ts):
    """With visits read only at the end cells (letters from P_j alone), the product is the layered
    planner: the same cost as plan_sequence for every sequence. With the tubes' letters it is never
    longer, and on 1 -> 3 -> 4 -> 5 -> 6 one step shorter: edge 14 -> 33 (L = 10) runs down the
    right column and its Q_7 lies inside region 3's cell 25, a visit plan_sequence cannot see
    (it goes 14 -> 25 -> 33, L = 7 + 4)."""
    ts = paper_ts
    d = ts.decomposition
    for seq in SEQUENCES:
        plain = plan_sequence(ts, 0, seq)
        dfa = sequence_dfa(seq)
        L = np.array([e.L for e in ts.edges])
        must = np.zeros((ts.n_edges, L.max()), np.int64)
        for k, e in enumerate(ts.edges):
            must[k, e.L - 1] = dfa.letter([] if d.labels[e.dst] is None else [d.labels[e.dst]])
        cells_only = plan_dfa(ts, 0, dfa, letters=EdgeLetters(must, must.copy(), L))
        assert cells_only.cost == plain.cost, seq
        sp = plan_sequence_spec(ts, 0, seq)
        assert sp.cost <= plain.cost, seq
        random_letters_accepted(ts, sp, draws=20)
    plain = plan_sequence(ts, 0, ["3", "4", "5", "6"])
    sp = plan_sequence_spec(ts, 0, ["3", "4", "5", "6"])
    assert (plain.cost, sp.cost) == (189, 188)
    assert plan_formula(ts, 0, "F(l3 & F(l4 & F(l5 & F(l6))))").cost == 188
    k = ts.edge_index()[14, 33]
    assert k in sp.plan.edges and edge_letters(ts, ["3"], [k]).must.any()


def test_sequence_errors_name_the_segment(blocked_ts):
    with pytest.raises(PlanningError, match="no cell carries label '9'"):
        plan_sequence_spec(blocked_ts, 0, ["4", "9"])
    assert plan_sequence_spec(blocked_ts, 0, ["4", "6"]).cost > 0


def test_plans_are_deterministic_and_report_stats(avoid_ts):
    a = plan_formula(avoid_ts, 0, "F(l3 & F(l2)) & G(!l4)")
    b = plan_formula(avoid_ts, 0, "F(l3 & F(l2)) & G(!l4)")
    assert a.plan.cells == b.plan.cells and a.plan.edges == b.plan.edges
    assert a.states[0] == a.dfa.initial or a.states[0] >= 0
    assert a.dfa.accepting[a.states[-1]]
    assert a.stats["product_nodes"] == avoid_ts.n_cells * a.dfa.n_states and a.stats["product_arcs"] > 0
    assert random_letters_accepted(avoid_ts, a) == a.cost + 1


def test_three_dimensional_box_grid():
    """n-D: cubes in a row a | . | c | b; every path from a to b passes c, so "never c" blocks "eventually b"."""
    from tubejax.abstraction import build_abstraction
    from tubejax.model.geometry import Ball
    from tubejax.analyses.spec import simulate_spec
    from tubejax.model.system import LinearSystem, box_input_set
    from tubejax.model.workspace.boxgrid import box_grid
    d = box_grid([0, 0, 0], [4, 1, 1], [4, 1, 1], labels={"a": ([0, 0, 0], [1, 1, 1]),
                                                          "c": ([2, 0, 0], [3, 1, 1]),
                                                          "b": ([3, 0, 0], [4, 1, 1])})
    ts = build_abstraction(d, LinearSystem(A=np.eye(3), B=0.5 * np.eye(3), U=box_input_set(1.0, 3), W=Ball(3, 0.1)),
                           L_max=8, progress=False)
    a = d.cells_with_label("a")[0]
    sp = plan_formula(ts, a, "F(lb & F(la))")
    assert d.labels[sp.plan.cells[-1]] == "a" and random_letters_accepted(ts, sp) == sp.cost + 1
    with pytest.raises(PlanningError, match="region b cannot be reached"):
        plan_formula(ts, a, "F(lb) & G(!lc)")
    s = simulate_spec(ts, sp, SimulationRuns(n_runs=50, mode="adversarial", seed=0)).summary()
    assert s["runs_satisfying_spec"] == 50 and s["tube_exits"] == 0
