"""Algorithm 2 with HiGHS: validation data, re-checks, simulation, files."""

import json
from pathlib import Path

import networkx as nx
import numpy as np
import pytest
from scipy.spatial import Delaunay

from tubejax.abstraction import build_abstraction
from tubejax.model.geometry import sample_uniform
from tubejax.transitions.file_format import FORMAT_VERSION
from tubejax.transitions.transition_system import TransitionSystem
from tubejax.model.workspace import load_grid_map, parse_grid_map

# a copy of shared/validation/corridor_expected.json (an independent implementation's edges)
VALIDATION = Path(__file__).resolve().parent / "data" / "corridor_expected.json"


def expected_edges(case):
    data = json.loads(VALIDATION.read_text())
    return {tuple(e) for e in data["cases"][case]["edges"]}


@pytest.fixture(scope="module")
def corridor_ts(corridor_path, paper_system):
    return build_abstraction(load_grid_map(corridor_path), paper_system(0.2), L_max=10, progress=False)


def test_corridor_matches_independent_implementation(corridor_ts, corridor_path, paper_system):
    got = {(e.src, e.dst, e.L) for e in corridor_ts.edges}
    assert got == expected_edges("tube, r = 0.2")
    ts05 = build_abstraction(load_grid_map(corridor_path), paper_system(0.05), L_max=10, progress=False)
    assert {(e.src, e.dst, e.L) for e in ts05.edges} == expected_edges("tube, r = 0.05")


def test_every_edge_rechecks_and_stats(corridor_ts):
    v = corridor_ts.verify()
    assert v.size == corridor_ts.n_edges and np.all(v <= 1e-9)
    s = corridor_ts.stats
    assert s["n_edges"] == corridor_ts.n_edges and s["n_cells"] == 21
    assert s["verdicts"]["edge"] == s["n_edges"]
    assert s["n_unconfirmed"] == 0
    assert all(e.margin >= -1e-9 for e in corridor_ts.edges)
    assert s["n_zero_margin"] >= 1              # minimal-L edges that are just enough


def simulate_edge(ts, k, rng, runs=40):
    """Algorithm 1 with barycentric coordinates from a Delaunay triangulation (independent of
    tubejax.analyses.control)."""
    e, tube = ts.edges[k], ts.tubes[k]
    prob = ts.problem(k)
    Q = tube.vertices(prob.Z, prob.source)                     # (L+1, n_v, n)
    x = sample_uniform(prob.source, rng, runs)
    for ell in range(e.L):
        tri = Delaunay(Q[ell])
        s = tri.find_simplex(x, tol=1e-9)
        assert np.all(s >= 0), "state left the tube"
        T = tri.transform[s]
        b = np.einsum("rij,rj->ri", T[:, :2], x - T[:, 2])
        bary = np.hstack([b, 1 - b.sum(axis=1, keepdims=True)])
        lam = np.zeros((runs, Q.shape[1]))
        np.put_along_axis(lam, tri.simplices[s], bary, axis=1)
        u = lam @ tube.u[ell]
        w = sample_uniform(ts.system.W, rng, runs)
        x = x @ ts.system.A.T + u @ ts.system.B.T + w
    return x


def test_every_edge_holds_in_simulation(corridor_ts):
    rng = np.random.default_rng(0)
    target = corridor_ts.decomposition.cells
    for k, e in enumerate(corridor_ts.edges):
        xL = simulate_edge(corridor_ts, k, rng)
        assert np.all(target[e.dst].contains(xL, tol=1e-9)), (e.src, e.dst)


def test_pruning_never_removes_an_edge(paper_system):
    d = parse_grid_map("..#.\n.#..\n....\n")
    s = paper_system(0.15)
    a = build_abstraction(d, s, L_max=8, pruning=True, progress=False)
    b = build_abstraction(d, s, L_max=8, pruning=False, progress=False)
    assert [(e.src, e.dst, e.L) for e in a.edges] == [(e.src, e.dst, e.L) for e in b.edges]
    assert a.stats["n_lps"] < b.stats["n_lps"] and a.stats["n_pruned"] > 0


def test_target_too_small_is_pruned_and_confirmed_infeasible(paper_system):
    d = parse_grid_map("...\n")
    s = paper_system(0.55)                                      # a 1.1-wide W never fits a unit cell
    a = build_abstraction(d, s, L_max=3, pruning=True, progress=False)
    b = build_abstraction(d, s, L_max=3, pruning=False, progress=False)
    assert a.n_edges == b.n_edges == 0
    assert a.stats["pruned"]["target_too_small"] == 6 * 3 and a.stats["n_lps"] == 0
    assert b.stats["verdicts"] == {"infeasible": 18}


def test_save_load_roundtrip_and_reverify(corridor_ts, tmp_path):
    jpath, npath = corridor_ts.save(tmp_path)
    data = json.loads(jpath.read_text())
    assert data["version"] == FORMAT_VERSION and data["margin_scaling"] == "state" and len(data["edges"]) == corridor_ts.n_edges
    assert set(data["edges"][0]) == {"from", "to", "L", "margin", "provenance", "proof"}
    assert set(data["cells"][0]) == {"id", "label", "grid", "vertices"}
    ts2 = TransitionSystem.load(tmp_path)
    assert [(e.src, e.dst, e.L) for e in ts2.edges] == [(e.src, e.dst, e.L) for e in corridor_ts.edges]
    assert np.all(ts2.verify() <= 1e-9)
    assert np.array_equal(ts2.decomposition.obstacle_case_matrix(),
                          corridor_ts.decomposition.obstacle_case_matrix())
    # a corrupted tube is caught on re-verification
    ts2.tubes[0] = ts2.tubes[0]._replace(eps=ts2.tubes[0].eps * 0.5)
    with pytest.raises(AssertionError, match="fail re-verification"):
        ts2.verify()
    data["version"] = 99
    jpath.write_text(json.dumps(data))
    with pytest.raises(ValueError, match="version"):
        TransitionSystem.load(tmp_path)


def test_networkx_export(corridor_ts):
    G = corridor_ts.to_networkx()
    assert G.number_of_nodes() == 21 and G.number_of_edges() == corridor_ts.n_edges
    e = corridor_ts.edges[0]
    assert G.edges[e.src, e.dst]["weight"] == e.L
    assert nx.is_strongly_connected(G)


@pytest.mark.parametrize("bad", [0, -1, 2.5])
def test_bad_L_max_refused(bad, paper_system):
    with pytest.raises(ValueError, match="L_max must be an integer >= 1"):
        build_abstraction(parse_grid_map("..\n"), paper_system(0.1), L_max=bad, progress=False)


def test_pruning_sound_on_a_triangulation():
    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set
    from tubejax.model.workspace import parse_polygon_workspace

    d = parse_polygon_workspace({"boundary": [[0, 0], [4, 0], [4, 3], [0, 3]],
                                 "obstacles": [[[1.5, 1], [2.5, 1], [2.5, 2], [1.5, 2]]], "max_area": 1.5},
                                name="small")
    s = LinearSystem(A=np.array([[1.0, 0.1], [0.0, 1.0]]), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.03))
    a = build_abstraction(d, s, zshape="regular", L_max=4, pruning=True, progress=False)
    b = build_abstraction(d, s, zshape="regular", L_max=4, pruning=False, progress=False)
    assert [(e.src, e.dst, e.L) for e in a.edges] == [(e.src, e.dst, e.L) for e in b.edges]
    assert a.n_edges > 0 and a.stats["n_pruned"] > 0


class _DeferringSolver:
    """HiGHS underneath; when asked to defer, every edge and every third non-edge come back
    as a Pending 'likely edge' (the non-edges play a PDHG tube that HiGHS refuses)."""

    supports_deferred = True

    def __init__(self):
        self.calls = []

    def __call__(self, problems, progress=None, defer=False):
        from concurrent.futures import Future

        from tubejax.lp.evidence.verdict import Pending, highs_solve_batch
        ref = highs_solve_batch(problems)
        self.calls.append(defer)
        if not defer:
            return ref
        out = []
        for k, v in enumerate(ref):
            if v.status == "edge" or k % 3 == 0:
                f = Future()
                f.set_result(v)
                out.append(Pending(f, "fake"))
            else:
                out.append(v)
        return out


def test_deferred_confirmations_give_algorithm_2s_result(corridor_path, paper_system, caplog):
    dec = load_grid_map(corridor_path)
    sysm = paper_system(0.2)
    ref = build_abstraction(dec, sysm, L_max=6, progress=False)
    solver = _DeferringSolver()
    rounds = []
    with caplog.at_level("WARNING", logger="tubejax"):
        ts = build_abstraction(dec, sysm, L_max=6, progress=False, solve_batch=solver,
                               on_round=lambda L, e, t: rounds.append(len(e)))
    assert {(e.src, e.dst): e.L for e in ts.edges} == {(e.src, e.dst): e.L for e in ref.edges}
    assert ts.n_edges > 10 and sum(rounds) == ts.n_edges
    assert "but HiGHS says infeasible" in caplog.text        # some pairs were reopened ...
    assert ts.stats["n_lps"] == ref.stats["n_lps"]            # ... and every instance was solved once
    assert np.all(ts.verify(tol=1e-9) <= 1e-9)


def test_run_stats_count_candidates_and_time_the_rounds(corridor_ts):
    from tubejax.abstraction.pruning import PRUNE_REASONS

    s = corridor_ts.stats
    N = s["n_cells"]
    assert s["n_pairs"] == N * (N - 1)
    assert 0 < s["n_obstacle_case_candidates"] <= s["n_tested_pairs"] <= s["n_candidate_pairs"] <= s["n_pairs"]
    assert set(s["pruned"]) == set(PRUNE_REASONS) and s["n_pruned"] == sum(s["pruned"].values())
    assert s["n_pruned"] + s["n_lps"] <= N * (N - 1) * s["L_max"]
    assert 0 < s["seconds_before_first_lp"] < s["seconds"]
    assert sum(r["n_lps"] for r in s["rounds"]) == s["n_lps"]
    assert [r["L"] for r in s["rounds"]] == sorted(r["L"] for r in s["rounds"])
    assert s["problem_seconds"] + s["solve_seconds"] <= s["seconds"]
    assert s["highs_lps_per_second"] > 0 and "pdhg_lps_per_second" not in s    # sequential HiGHS


def test_lp_rates_from_solver_counters():
    from tubejax.abstraction.rounds import lp_rates as _lp_rates

    before = {"n_lps": 10, "pdhg_seconds": 1.0, "sent_to_highs": 1, "highs_confirmations": 2,
              "highs_cpu_seconds": 0.5}
    after = {"n_lps": 110, "pdhg_seconds": 3.0, "sent_to_highs": 5, "highs_confirmations": 12,
             "highs_cpu_seconds": 1.5}
    r = _lp_rates(before, after, {"n_lps": 100, "solve_seconds": 4.0})
    assert r == {"pdhg_lps_per_second": 50.0, "highs_lps_per_second": 14.0, "n_highs_solves": 14}
