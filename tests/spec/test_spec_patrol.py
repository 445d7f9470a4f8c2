"""Patrolling: the cheapest cycle through the regions in order, reached from the start, repeated."""

import networkx as nx
import numpy as np
import pytest

from tubejax.analyses.control import SimulationRuns, PlanningError
from tubejax.analyses.spec import edge_letters, plan_patrol, simulate_spec


def graph(ts, avoid=()):
    lt = edge_letters(ts, list(avoid)) if avoid else None
    G = nx.DiGraph()
    for k, e in enumerate(ts.edges):
        if lt is not None and lt.may[k].any():
            continue
        if not G.has_edge(e.src, e.dst) or G[e.src][e.dst]["weight"] > e.L:
            G.add_edge(e.src, e.dst, weight=e.L)
    return G


def brute_force_cycle(ts, labels, avoid=()):
    """min over anchors a (label 0) and target cells of dist(a, c1) + dist(c1, c2) + ... + dist(c_m, a)."""
    G = graph(ts, avoid)
    d = ts.decomposition
    dist = dict(nx.all_pairs_dijkstra_path_length(G, weight="weight"))

    def d_(u, v):                                  # at least one edge when returning to the anchor
        if u != v:
            return dist.get(u, {}).get(v, np.inf)
        return min((G[u][x]["weight"] + dist.get(x, {}).get(u, np.inf) for x in G[u]), default=np.inf)

    best = np.inf
    for a in d.cells_with_label(labels[0]):
        costs = {a: 0.0}
        for l in labels[1:]:
            costs = {c: min(v + dist.get(u, {}).get(c, np.inf) for u, v in costs.items())
                     for c in d.cells_with_label(l)}
        best = min(best, min(v + d_(u, a) for u, v in costs.items()))
    return best


def test_patrol_cycle_is_cheapest_and_repeated(avoid_ts):
    ts = avoid_ts
    sp = plan_patrol(ts, 0, ["3", "2"], cycles=3, avoid=["4"])
    st = sp.stats
    assert st["cycle_steps"] == brute_force_cycle(ts, ["3", "2"], ["4"])
    assert sp.cost == st["prefix_steps"] + 3 * st["cycle_steps"]
    a = st["anchor"]
    assert ts.decomposition.labels[a] == "3" and sp.plan.cells[0] == 0 and sp.plan.cells[-1] == a
    assert sp.plan.labels == ["3", "2", "3", "2", "3", "2", "3"]
    labs = ts.decomposition.labels
    for k, end in enumerate(sp.plan.segment_ends):
        assert labs[sp.plan.cells[end]] == sp.plan.labels[k]
    lt = edge_letters(ts, ["4"], sp.plan.edges)
    assert not lt.may.any()                                   # no tube meets region 4
    assert sp.dfa.accepting[sp.states[-1]] and sp.kind == "patrol" and sp.avoid == ("4",)


def test_patrol_without_avoid_and_single_region(avoid_ts):
    ts = avoid_ts
    sp = plan_patrol(ts, 0, ["2", "3"], cycles=1)
    assert sp.stats["cycle_steps"] == brute_force_cycle(ts, ["2", "3"])
    one = plan_patrol(ts, 0, ["3"], cycles=2)                   # leave region 3 and come back
    assert one.stats["cycle_steps"] == brute_force_cycle(ts, ["3"]) > 0


def test_patrol_simulation_runs_the_cycles(avoid_ts):
    sp = plan_patrol(avoid_ts, 0, ["3", "2"], cycles=2, avoid=["4"])
    s = simulate_spec(avoid_ts, sp, SimulationRuns(n_runs=300, mode="adversarial", seed=4)).summary()
    assert s["steps"] == sp.cost and s["runs_satisfying_spec"] == 300
    assert s["avoided_region_entries"] == 0 and s["tube_exits"] == 0 and s["obstacle_entries"] == 0
    assert s["targets_reached_per_segment"] == [300] * 5


def test_patrol_errors(avoid_ts, blocked_ts):
    with pytest.raises(PlanningError, match="no cell carries label '9'"):
        plan_patrol(avoid_ts, 0, ["3", "9"])
    with pytest.raises(PlanningError, match="both patrolled and avoided"):
        plan_patrol(avoid_ts, 0, ["3", "4"], avoid=["4"])
    with pytest.raises(PlanningError, match="start cell 0 lies in the avoided region 1"):
        plan_patrol(avoid_ts, 0, ["3"], avoid=["1"])
    with pytest.raises(PlanningError, match="cycles must be an integer >= 1"):
        plan_patrol(avoid_ts, 0, ["3"], cycles=0)
    with pytest.raises(PlanningError, match=r"no cell labelled 6 is reachable from cell 0 \(edges whose "
                                            r"tubes may meet regions 4 are not used\)"):
        plan_patrol(blocked_ts, 0, ["6", "1"], avoid=["4"])
