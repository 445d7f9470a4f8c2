"""The drone's flight through two storeys (conf/experiment/drone6d_tiny.yaml, docs/math/drone.md).

The 6-D drone over the tiny generated two-storey building (28 voxels, unit look-ahead slabs: 1,008
cells), by the product path, verified, planned from region 1 (bottom storey) to region 2 (top
storey) and simulated under adversarial disturbances in float64. Checked independently of the
monitor's own sums:

* the runs start in storey 1 (``z <= 1``) and end in storey 2 (``z >= 2``), through the slab;
* Algorithm 1 runs in 6-D: ``Z`` (the cell) has 64 vertices, every control step's barycentric map
  is a real triangulation (not the zero map of a point tube), and the weights it gives are
  convex and reproduce the state from the tube set's 64 vertices (``x = sum lambda_k q_k(l)``)
  and the applied input from the vertex inputs (``u = sum lambda_k u_k(l)``);
* the monitor flags what goes wrong: runs pushed by a disturbance beyond ``W`` leave their tubes,
  and vertex inputs scaled outside ``U`` are reported as inputs outside ``U``.
"""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import yaml

import tubejax as tj
from tubejax.abstraction.product_abstraction import build_product_abstraction
from tubejax.abstraction.product_transitions import product_transition_system
from tubejax.analyses.control import simulate
from tubejax.analyses.control.controller import control_step, plan_controller
from tubejax.analyses.control.simulate import SimulationRuns, summary_violations
from tubejax.inputs import ProblemInputs
from tubejax.model.geometry import Ball
from tubejax.model.zshape.kinds import source_points
from tubejax.verify.product_check import verify_product

#: The abstraction of 1,008 cells (factor LPs, join, exact verification) takes about a minute of CPU.
pytestmark = pytest.mark.slow

CONF = Path(__file__).resolve().parents[1] / "conf"
RUNS = 400
#: Fewest simplices of any triangulation of the 6-cube (Hughes 1993): a triangulation of Z with
#: fewer is degenerate.
MIN_SIMPLICES_6CUBE = 308


@pytest.fixture(scope="module")
def flight():
    exp = yaml.safe_load((CONF / "experiment" / "drone6d_tiny.yaml").read_text())
    ws = yaml.safe_load((CONF / "workspace" / "building3d_tiny.yaml").read_text())
    ws["map_file"] = str(CONF.parent / ws["map_file"])
    ws["velocity_divisions"] = exp["workspace"]["velocity_divisions"]
    system = yaml.safe_load((CONF / "system" / "drone6d.yaml").read_text())
    inputs = ProblemInputs.from_dict({"workspace": ws, "system": system,
                                      "disturbance": {"kind": "ball", "radius": exp["disturbance"]["radius"]}})
    d = inputs.build_decomposition()
    ps = build_product_abstraction(d, inputs.build_system(), Z=inputs.build_cross_sections(d), L_max=exp["L_max"])
    report = verify_product(ps, exact=True, enumerate_join=True)
    ts = product_transition_system(ps)
    plan = tj.plan(ts, exp["spec"]["sequence"]).plan
    return ts, plan, report


def test_the_tiny_building_is_1008_cells_in_r6_and_verified(flight):
    ts, plan, report = flight
    assert report.ok, report.problems[:3]
    assert ts.decomposition.dim == 6 and ts.n_cells == 28 * 4 * 3 * 3
    assert ts.n_edges > 0 and plan.edges


def test_adversarial_runs_fly_from_storey_1_to_storey_2_safely(flight):
    ts, plan, _ = flight
    res = simulate(ts, plan, SimulationRuns(n_runs=RUNS, mode="adversarial", seed=11))
    s = res.summary()
    assert summary_violations(s) == [], summary_violations(s)
    assert res.trajectories.dtype == np.float64
    assert np.all(res.violation <= 1e-9) and np.all(res.input_violation <= 1e-9)
    z = res.trajectories[:, :, 4]                           # the height p_z (state axis 4)
    assert np.all(z[:, 0] <= 1.0) and np.all(z[:, -1] >= 2.0)   # storey 1 (layer 0) -> storey 2 (layer 2)
    base = ts.decomposition.cells[plan.cells[0]]
    assert np.all(base.violation(res.trajectories[:, 0]) <= 1e-9)


def _step_vertices(ts, plan):
    """Per control step ``t``: the tube set's vertices ``(n_v, n)`` the weights refer to and the vertex
    inputs ``(n_v, m)``, from the tubes (not from the controller's data)."""
    V, U = [], []
    for k in plan.edges:
        e, tube = ts.edges[k], ts.tubes[k]
        Z = ts.z_of(e.src, e.dst)
        q = tube.vertices(Z, ts.decomposition.cells[e.src])            # (L + 1, n_v, n)
        for l in range(int(e.L)):
            V.append(source_points(ts.decomposition.cells[e.src], Z.n_vertices).vertices if l == 0 else q[l])
            U.append(np.asarray(tube.u[l], float))
    return V, U


def test_algorithm1_uses_convex_weights_over_a_6d_triangulation(flight):
    ts, plan, _ = flight
    e = ts.edges[plan.edges[0]]
    assert ts.z_of(e.src, e.dst).n_vertices == 64
    res = simulate(ts, plan, SimulationRuns(n_runs=40, mode="adversarial", seed=2))
    V, U = _step_vertices(ts, plan)
    with jax.enable_x64(True):
        ctrl = plan_controller(ts, plan, jnp.float64)
        assert ctrl.n_steps == plan.cost == len(V)
        valid = np.asarray(ctrl.valid)
        assert np.all(valid.sum(axis=1) >= MIN_SIMPLICES_6CUBE)
        T = np.asarray(ctrl.T)
        assert np.all(np.abs(T[valid]).sum(axis=(1, 2)) > 0)          # no zero (point-tube) maps
        step = jax.jit(jax.vmap(control_step, in_axes=(0, None, None, None, None, None)))
        for t in range(ctrl.n_steps):
            x = res.trajectories[:, t]
            u, lam, outside = (np.asarray(a) for a in step(jnp.asarray(x), ctrl.T[t], ctrl.r[t],
                                                            ctrl.simplices[t], ctrl.valid[t], ctrl.u[t]))
            lam = lam[:, :len(V[t])]
            assert np.all(outside == 0) and np.all(lam >= 0)
            assert np.all((lam > 0).sum(axis=1) <= 7)                 # one simplex of R^6
            np.testing.assert_allclose(lam.sum(axis=1), 1.0, atol=1e-12)
            np.testing.assert_allclose(lam @ V[t], x, atol=1e-9)       # the state from the 64 vertices
            np.testing.assert_allclose(lam @ U[t], u, atol=1e-12)
            np.testing.assert_allclose(u, res.inputs[:, t], atol=1e-12)  # what the rollout applied


def test_the_monitor_flags_disturbances_beyond_w_and_inputs_outside_u(flight):
    ts, plan, _ = flight
    big = simulate(ts, plan, SimulationRuns(n_runs=50, mode="adversarial", seed=3, W=Ball(6, 0.3)))
    s = big.summary()
    assert s["tube_exits"] > 0 and any("tube exits" in b for b in summary_violations(s))
    with jax.enable_x64(True):
        ctrl = plan_controller(ts, plan, jnp.float64)
        loud = simulate(ts, plan, SimulationRuns(n_runs=20, mode="none", seed=4), ctrl=ctrl._replace(u=1.5 * ctrl.u))
    s = loud.summary()
    assert s["max_input_violation"] > 0.1
    assert any("inputs outside U" in b for b in summary_violations(s))
