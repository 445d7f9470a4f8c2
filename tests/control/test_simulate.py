"""Closed-loop simulation: the guarantees hold with the design W, violations are detected."""

import dataclasses

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from tubejax.analyses.control import (SimulationRuns, in_obstacle_interior, plan_controller,  # noqa: E402
                                      plan_sequence, sample_polytope, simulate, simulate_edge, trace_count)
from tubejax.model.geometry import Ball, Polytope  # noqa: E402
from tubejax.lp.declarations.tube_variables import Tube  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402

RUNS = 300


@pytest.fixture(scope="module")
def corridor():
    from tubejax.abstraction import build_abstraction
    from tubejax.model.workspace.gridmap import load_grid_map
    d = load_grid_map("/work/shared/validation/corridor.txt")
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    ts = build_abstraction(d, s, L_max=10, progress=False)
    start = d.cells_with_label("1")[0]
    plan = plan_sequence(ts, start, ["2", "1"])
    return ts, plan, plan_controller(ts, plan)


def assert_safe(res):
    s = res.summary()
    assert s["runs"] == RUNS
    assert s["obstacle_entries"] == 0
    assert s["tube_exits"] == 0
    assert s["workspace_exits"] == 0
    assert s["runs_reaching_all_targets"] == RUNS
    assert s["max_tube_violation"] <= 1e-9
    assert s["max_outside"] <= 1e-9
    assert s["max_input_violation"] <= 1e-9
    assert np.all(res.first_exit_time == -1) and np.all(res.first_obstacle_time == -1)


@pytest.mark.parametrize("mode", ["uniform", "boundary", "adversarial"])
def test_corridor_design_disturbance_is_safe(corridor, mode):
    ts, plan, ctrl = corridor
    res = simulate(ts, plan, SimulationRuns(n_runs=RUNS, mode=mode, seed=3), ctrl=ctrl)
    assert_safe(res)
    T = plan.cost
    assert res.trajectories.shape == (RUNS, T + 1, 2)
    assert res.inputs.shape == (RUNS, T, 2) and res.disturbances.shape == (RUNS, T, 2)
    assert res.targets_reached.shape == (RUNS, 2)
    nw = np.linalg.norm(res.disturbances, axis=-1)
    assert np.all(nw <= 0.2 + 1e-12)
    if mode != "uniform":
        assert np.allclose(nw, 0.2)
    else:
        assert nw.min() < 0.1
    # the initial states are spread over the start cell
    start = ts.decomposition.cells[plan.cells[0]]
    assert np.all(start.contains(res.trajectories[:, 0]))
    assert np.ptp(res.trajectories[:, 0], axis=0).min() > 0.8


def test_polytope_disturbance(corridor):
    ts, plan, ctrl = corridor
    W = Polytope.box([-0.14, -0.14], [0.14, 0.14])          # inside the design ball
    for mode in ("uniform", "boundary", "adversarial"):
        res = simulate(ts, plan, SimulationRuns(n_runs=RUNS, mode=mode, seed=1, W=W), ctrl=ctrl)
        assert_safe(res)
        w = res.disturbances.reshape(-1, 2)
        assert np.all(W.contains(w, tol=1e-12))
        if mode != "uniform":
            assert np.allclose(W.violation(w), 0.0, atol=1e-12)
        if mode == "adversarial":
            assert np.allclose(np.abs(w), 0.14)               # a vertex of the box


def test_larger_disturbance_is_detected(corridor):
    ts, plan, ctrl = corridor
    res = simulate(ts, plan, SimulationRuns(n_runs=RUNS, mode="adversarial", seed=0, W=Ball(2, 0.3)), ctrl=ctrl)
    s = res.summary()
    assert s["tube_exits"] > 0 and s["max_tube_violation"] > 1e-3
    assert np.all(res.first_exit_time[res.tube_exit] >= 1)
    assert s["max_outside"] > 0
    assert s["max_input_violation"] <= 1e-9                  # inputs stay in U even outside
    res_u = simulate(ts, plan, SimulationRuns(n_runs=RUNS, mode="boundary", seed=0, W=Ball(2, 0.3)), ctrl=ctrl)
    assert res_u.summary()["tube_exits"] > 0


def test_shrunken_tube_is_detected(corridor):
    ts, plan, ctrl = corridor
    k = plan.edges[1]
    t = ts.tubes[k]
    bad = list(ts.tubes)
    bad[k] = Tube(t.p, 0.5 * t.eps, t.u)
    ts_bad = dataclasses.replace(ts, tubes=bad)
    res = simulate(ts_bad, plan, SimulationRuns(n_runs=RUNS, mode="uniform", seed=0))   # same shapes: no compile
    assert res.summary()["tube_exits"] > 0
    L0 = plan.steps[0]
    assert np.all(res.first_exit_time[res.tube_exit] > L0)           # exits happen on edge 2


def test_simulate_single_edge(corridor):
    ts, _, _ = corridor
    k = 0
    ok = simulate_edge(ts, k, SimulationRuns(n_runs=RUNS, mode="adversarial", seed=0))
    assert_safe(ok)
    e = ts.edges[k]
    assert ok.trajectories.shape[1] == e.L + 1
    assert np.all(ts.decomposition.cells[e.dst].contains(ok.trajectories[:, -1]))


def test_initial_state_outside_is_flagged(corridor):
    ts, plan, ctrl = corridor
    x0 = np.array([[0.5, 3.5], [2.5, 3.5]] * (RUNS // 2))      # odd rows start outside cell 0
    res = simulate(ts, plan, SimulationRuns(mode="none"), x0=x0, ctrl=ctrl)    # RUNS rows: reuses the compile
    assert list(res.tube_exit[:4]) == [False, True, False, True]
    assert res.first_exit_time[1] == 0 and res.first_exit_time[0] == -1


def test_obstacle_interior_test(corridor):
    ts, _, _ = corridor
    d = ts.decomposition
    pts = np.array([[1.5, 1.5],       # inside the obstacle block (1,1)-(2,3)
                    [1.0, 1.5],       # on its boundary, shared with a free cell
                    [0.5, 3.5],       # free cell
                    [3.5, 0.5]])      # obstacle square (3,0)-(4,1)
    assert list(in_obstacle_interior(d, pts)) == [True, False, False, True]
    P = Polytope.box([1.0, 1.0], [2.0, 2.0])                 # convex obstacles work too
    d2 = dataclasses.replace(d, obstacles=(P,))
    got = in_obstacle_interior(d2, np.array([[1.5, 1.5], [1.5, 2.5], [0.5, 0.5], [1.0, 1.5]]))
    assert list(got) == [True, False, False, False]


def test_seeds_and_no_recompile(corridor):
    ts, plan, ctrl = corridor
    a = simulate(ts, plan, SimulationRuns(n_runs=RUNS, mode="uniform", seed=5), ctrl=ctrl)
    n = trace_count()
    b = simulate(ts, plan, SimulationRuns(n_runs=RUNS, mode="uniform", seed=5), ctrl=ctrl)
    c = simulate(ts, plan, SimulationRuns(n_runs=RUNS, mode="boundary", seed=6), ctrl=ctrl)
    assert trace_count() == n              # same shapes (any mode, any seed): no new trace
    assert np.array_equal(a.trajectories, b.trajectories)
    assert not np.allclose(a.trajectories, c.trajectories)


def test_sample_polytope_uniform():
    P = Polytope.from_vertices([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0], [1.0, 1.5]])
    x = np.asarray(sample_polytope(jax.random.PRNGKey(0), P, 4000))
    assert np.all(P.contains(x, tol=1e-12))
    # area fractions: rectangle 2 of 2.5 total
    assert abs(np.mean(x[:, 1] <= 1.0) - 0.8) < 0.03


def test_bad_mode(corridor):
    ts, plan, ctrl = corridor
    with pytest.raises(ValueError, match="mode"):
        simulate(ts, plan, SimulationRuns(n_runs=2, mode="worst"), ctrl=ctrl)


def test_three_dimensional_box_grid():
    """n-D path: 3-D cubes (8 vertices, Delaunay in 3-D), polytope W, every mode."""
    from tubejax.abstraction import build_abstraction
    from tubejax.analyses.control import MODES
    from tubejax.model.workspace.boxgrid import box_grid
    d = box_grid([0, 0, 0], [3, 1, 1], [3, 1, 1],
                 labels={"a": ([0, 0, 0], [1, 1, 1]), "b": ([2, 0, 0], [3, 1, 1])})
    s = LinearSystem(A=np.eye(3), B=0.5 * np.eye(3), U=box_input_set(1.0, 3), W=Ball(3, 0.1))
    ts = build_abstraction(d, s, L_max=8, progress=False)
    plan = plan_sequence(ts, d.cells_with_label("a")[0], ["b", "a"])
    ctrl = plan_controller(ts, plan)
    W = Polytope.box(-0.057 * np.ones(3), 0.057 * np.ones(3))    # inside the design ball
    for mode in MODES:
        res = simulate(ts, plan, SimulationRuns(n_runs=RUNS, mode=mode, seed=2, W=W), ctrl=ctrl)
        assert_safe(res)
        assert res.trajectories.shape == (RUNS, plan.cost + 1, 3)
    wide = Polytope.box(-0.2 * np.ones(3), 0.2 * np.ones(3))
    big = simulate(ts, plan, SimulationRuns(n_runs=RUNS, mode="adversarial", W=wide), ctrl=ctrl)
    assert big.summary()["tube_exits"] > 0


_F64 = '''
import jax, numpy as np
assert not jax.config.jax_enable_x64
from tubejax.abstraction import build_abstraction
from tubejax.analyses.control import SimulationRuns, plan_sequence, simulate
from tubejax.model.geometry import Ball
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace.gridmap import parse_grid_map
dec = parse_grid_map("1..2\\n.#..\\n...3\\n")
sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1))
ts = build_abstraction(dec, sysm, L_max=6, progress=False)
plan = plan_sequence(ts, dec.cells_with_label("1")[0], ["2"])
res = simulate(ts, plan, SimulationRuns(n_runs=50, mode="adversarial", seed=0))
s = res.summary()
assert res.trajectories.dtype == np.float64
assert s["obstacle_entries"] == 0 and s["tube_exits"] == 0 and s["runs_reaching_all_targets"] == 50, s
assert not jax.config.jax_enable_x64          # the global setting is left alone
print("OK", s["max_tube_violation"])
'''


def test_simulation_is_float64_without_global_x64():
    """Everything that reports safety computes in float64, whatever ``jax_enable_x64`` says."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    env = {k: v for k, v in os.environ.items() if k != "JAX_ENABLE_X64"}
    res = subprocess.run([sys.executable, "-c", _F64], cwd=root, env=env, capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert any(line.startswith("OK ") for line in res.stdout.splitlines()), res.stdout
