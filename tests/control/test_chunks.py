"""Issue 21 (resources): many runs and long plans in chunks of bounded memory.

A simulation that fits in one chunk is the unchunked one, number for number; in chunks, each
chunk is the simulation of its own seed, the summary adds them up, and a plan of which one run
cannot fit is refused up front with the memory it needs. The host checks (cells tried in plan
order, facets without a stacked matmul) give the same answers as the plain definitions."""

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import shapely  # noqa: E402

from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.analyses.control import (edge_controller, in_cells, in_obstacle_interior, plan_controller,  # noqa: E402
                                      plan_sequence, simulate)
from tubejax.analyses.control.chunks import (CHUNK_BYTES, SimulationTooLarge, chunk_runs, chunk_seed,  # noqa: E402
                                             merge_summaries, run_step_bytes, simulate_in_chunks)
from tubejax.analyses.control.controller import require_tubes  # noqa: E402
from tubejax.errors import InputError  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.analyses.spec import plan_patrol  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace.gridmap import load_grid_map  # noqa: E402
from tubejax.analyses.control import SimulationRuns  # noqa: E402


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    m = tmp_path_factory.mktemp("tiny") / "tiny.txt"
    m.write_text("1..\n.#.\n..2\n")
    d = load_grid_map(str(m))
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    ts = build_abstraction(d, s, L_max=6, progress=False)
    return ts, plan_sequence(ts, d.cells_with_label("1")[0], ["2"])


def _run(ts, plan, mode="adversarial"):
    def one(n, seed):
        res = simulate(ts, plan, SimulationRuns(n_runs=n, mode=mode, seed=seed))
        return res, res.summary()
    return one


def test_one_chunk_is_the_unchunked_simulation(tiny):
    ts, plan = tiny
    per = chunk_runs(ts, plan, 500)
    assert per == 500                                        # a normal size: one chunk
    res, s = simulate_in_chunks(_run(ts, plan, "uniform"), 500, 3, per)
    direct = simulate(ts, plan, SimulationRuns(n_runs=500, mode="uniform", seed=3))
    assert s == direct.summary() and "chunks" not in s
    np.testing.assert_array_equal(res.trajectories, direct.trajectories)


def test_chunks_add_up_and_repeat(tiny):
    ts, plan = tiny
    res, s = simulate_in_chunks(_run(ts, plan), 250, 11, 100)
    assert s["runs"] == 250 and s["chunks"] == 3 and s["runs_per_chunk"] == 100 and s["seed"] == 11
    parts = [simulate(ts, plan, SimulationRuns(n_runs=n, mode="adversarial", seed=chunk_seed(11, c))).summary()
             for c, n in enumerate((100, 100, 50))]            # each chunk is the simulation of its seed
    assert s["runs_reaching_all_targets"] == sum(p["runs_reaching_all_targets"] for p in parts) == 250
    assert s["max_tube_violation"] == max(p["max_tube_violation"] for p in parts) <= 1e-9
    assert s["targets_reached_per_segment"] == [250] * len(parts[0]["targets_reached_per_segment"])
    assert res.n_runs == 100                                  # the first chunk's runs, for figures
    assert simulate_in_chunks(_run(ts, plan), 250, 11, 100)[1] == s      # same seed, same numbers
    assert len({chunk_seed(11, c) for c in range(50)} | {chunk_seed(12, 0)}) == 51


def test_merge_summaries():
    a = {"runs": 2, "tube_exits": 1, "max_outside": 0.5, "targets_reached_per_segment": [2, 1], "mode": "x"}
    b = {"runs": 3, "tube_exits": 0, "max_outside": 0.25, "targets_reached_per_segment": [3, 3], "mode": "x"}
    assert merge_summaries([a, b]) == {"runs": 5, "tube_exits": 1, "max_outside": 0.5,
                                       "targets_reached_per_segment": [5, 4], "mode": "x"}


def test_chunk_sizes_bound_the_memory_and_a_run_too_large_is_refused(tiny):
    ts, plan = tiny
    per = chunk_runs(ts, plan, 10 ** 7)
    assert per < 10 ** 7 and per * (plan.cost + 1) * run_step_bytes(2, 2, 4) <= CHUNK_BYTES
    long = plan_patrol(ts, plan.cells[0], ["1", "2"], cycles=10 ** 4).plan
    assert chunk_runs(ts, long, 50) < 50                      # a long patrol: a few runs per chunk
    with pytest.raises(SimulationTooLarge, match=r"the plan has [\d,]+ steps: one run of it needs about "):
        chunk_runs(ts, long, 50, limit_bytes=64 << 20)


def test_plan_controller_is_the_edges_controllers_joined(tiny):
    ts, _ = tiny
    plan = plan_patrol(ts, ts.decomposition.cells_with_label("1")[0], ["1", "2"], cycles=3).plan
    c = plan_controller(ts, plan, np.float64)
    parts = [edge_controller(ts, k, np.float64) for k in plan.edges]
    for f in ("T", "r", "simplices", "valid", "u"):
        np.testing.assert_array_equal(np.asarray(getattr(c, f)), np.concatenate([getattr(p, f) for p in parts]))
    for f in ("H", "h"):                                      # consecutive edges share a time instant
        want = np.concatenate([getattr(parts[0], f)] + [getattr(p, f)[1:] for p in parts[1:]])
        np.testing.assert_array_equal(np.asarray(getattr(c, f)), want)


def test_host_checks_equal_their_definitions(tiny):
    ts, plan = tiny
    d = ts.decomposition
    rng = np.random.default_rng(0)
    X = np.concatenate([rng.uniform(-0.5, 3.5, (4000, 2)), rng.integers(0, 4, (500, 2)).astype(float),
                        [[1.5, 1.5], [1.0, 1.5], [1.2, 1.0 - 1e-12]]]).reshape(3, -1, 2)
    brute = np.zeros(X.shape[:-1], bool)
    for P in d.cells:
        brute |= np.max(X @ P.H.T - P.h, axis=-1) <= 1e-9
    np.testing.assert_array_equal(in_cells(d, X), brute)
    np.testing.assert_array_equal(in_cells(d, X, first=plan.cells[::-1]), brute)
    np.testing.assert_array_equal(in_cells(d, X, cells=[0, 5], first=[5, 7]),
                                  (np.max(X @ d.cells[0].H.T - d.cells[0].h, axis=-1) <= 1e-9)
                                  | (np.max(X @ d.cells[5].H.T - d.cells[5].h, axis=-1) <= 1e-9))
    inside = np.zeros(X.shape[:-1], bool)
    for o in d.obstacles:                                     # a grid map's obstacles are shapely polygons
        inside |= shapely.contains_xy(o, X[..., 0], X[..., 1])
    np.testing.assert_array_equal(in_obstacle_interior(d, X), inside & ~brute)
    assert inside.any() and (~brute).any()


def test_systems_without_tubes_have_no_controller(tiny):
    import dataclasses
    ts, plan = tiny
    for method in ("exact2d", "openloop"):
        other = dataclasses.replace(ts, method=method)
        with pytest.raises(InputError, match=f"method '{method}': the system stores"):
            plan_controller(other, plan)
    broken = dataclasses.replace(ts, tubes=[None] * ts.n_edges)
    with pytest.raises(InputError, match=r"edge \d+ \(\d+->\d+, L=\d+\): no tube stored"):
        require_tubes(broken, plan.edges)
