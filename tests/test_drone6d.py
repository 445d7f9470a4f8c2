"""The 6-D drone (conf/system/drone6d.yaml): three double integrators in look-ahead coordinates.

``A`` and ``B`` against a hand derivation (the exact zero-order-hold discretisation of each axis,
by the matrix exponential, then the change to ``(p, s = p + beta v)``); Algorithm 1 in 6-D on a
tiny lifted map: adversarial closed-loop runs stay in their tubes (float64 monitor).
"""

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.linalg import expm

import tubejax as tj
from tubejax.abstraction import build_abstraction
from tubejax.errors import InputModelError
from tubejax.inputs import ProblemInputs
from tubejax.inputs.problem_inputs import from_record
from tubejax.inputs.dynamics import SystemModel
from tubejax.model.geometry import Ball
from tubejax.model.system import LinearSystem
from tubejax.model.system_kinds import SYSTEM_KINDS, double_integrator_lookahead, lookahead_to_velocity
from tubejax.model.workspace import box_grid
from tubejax.model.workspace.lookahead import lift_lookahead

CONF = Path(__file__).resolve().parents[1] / "conf"


def hand_derived(dt: float, beta: float, axes: int):
    """Exact ZOH of x'' = a per axis (expm of the augmented generator), then T = [[1, 0], [1, beta]]."""
    M = np.zeros((3, 3))
    M[0, 1] = M[1, 2] = 1.0                     # d/dt (p, v, a) = (v, a, 0)
    E = expm(M * dt)
    A1, B1 = E[:2, :2], E[:2, 2:]
    T = np.array([[1.0, 0.0], [1.0, beta]])
    return np.kron(np.eye(axes), T @ A1 @ np.linalg.inv(T)), np.kron(np.eye(axes), T @ B1)


@pytest.mark.parametrize("dt,beta", [(0.5, 2.0), (0.25, 1.0), (0.1, 3.0)])
def test_a_and_b_are_the_exact_discretisation_in_lookahead_coordinates(dt, beta):
    A, B = double_integrator_lookahead(3, dt, beta)
    Ah, Bh = hand_derived(dt, beta, 3)
    np.testing.assert_allclose(A.astype(float), Ah, rtol=0, atol=1e-14)
    np.testing.assert_allclose(B.astype(float), Bh, rtol=0, atol=1e-14)


def test_the_derivation_is_exact_rational():
    A, B = double_integrator_lookahead(3, 0.1, 3.0)       # 0.1 is 1/10, not its binary float
    assert A[0, 0] == Fraction(29, 30) and A[1, 0] == Fraction(-1, 30) and A[1, 1] == Fraction(31, 30)
    assert B[0, 0] == Fraction(1, 200) and B[1, 0] == Fraction(1, 200) + Fraction(3, 10)
    assert all(isinstance(x, Fraction) for x in A.ravel())


def test_config_system_is_the_derivation():
    data = yaml.safe_load((CONF / "system" / "drone6d.yaml").read_text())
    assert data["kind"] in SYSTEM_KINDS and "A" not in data and "B" not in data
    m = SystemModel.model_validate(data)
    Ah, Bh = hand_derived(data["dt"], data["beta"], 3)
    np.testing.assert_allclose(np.array(m.A), Ah, atol=1e-14)
    np.testing.assert_allclose(np.array(m.B), Bh, atol=1e-14)
    assert m.n == 6 and m.m == 3
    # the 4-D preset's written A, B are this kind's with two axes
    di = yaml.safe_load((CONF / "system" / "double_integrator.yaml").read_text())
    A2, B2 = double_integrator_lookahead(2, di["dt"], di["beta"])
    np.testing.assert_array_equal(np.array(di["A"], float), A2.astype(float))
    np.testing.assert_array_equal(np.array(di["B"], float), B2.astype(float))


def _inputs(system):
    return {"workspace": {"kind": "grid", "map_file": str(CONF / "workspace" / "maps" / "building3d.txt"),
                          "velocity_divisions": 1},
            "system": system, "disturbance": {"kind": "ball", "radius": 0.01}}


@pytest.mark.parametrize("change,field", [({"kind": "triple_integrator"}, "system.kind"),
                                          ({"dt": None}, "system.dt"), ({"dt": -0.5}, "system.dt"),
                                          ({"beta": "two"}, "system.beta"), ({"axes": 0}, "system.axes"),
                                          ({"A": [[1.0] * 6] * 6}, "system.A")])
def test_bad_system_kind_values_name_the_field(change, field):
    system = {"kind": "double_integrator", "axes": 3, "dt": 0.5, "beta": 2.0, "U": {"kind": "box", "bound": 1.0}}
    system.update(change)
    system = {k: v for k, v in system.items() if v is not None}
    with pytest.raises(InputModelError) as exc:
        ProblemInputs.from_dict(_inputs(system))
    assert field in str(exc.value)


def test_the_inputs_record_rebuilds_the_same_system():
    system = yaml.safe_load((CONF / "system" / "drone6d.yaml").read_text())
    inputs = ProblemInputs.from_dict(_inputs(system))
    again = from_record(inputs.record())
    assert again.build_system().differences(inputs.build_system()) == []


def test_lookahead_to_velocity():
    x = np.array([[1.0, 3.0, 0.0, -2.0, 2.0, 2.0]])
    p, v = lookahead_to_velocity(x, 2.0)
    np.testing.assert_array_equal(p, [[1.0, 0.0, 2.0]])
    np.testing.assert_array_equal(v, [[1.0, -1.0, 0.0]])


@pytest.fixture(scope="module")
def tiny_ts():
    """Two voxels along x, look-ahead x in two slabs: 4 cells in R^6, joint tube LPs (seconds)."""
    A, B = double_integrator_lookahead(3, 0.5, 2.0)
    system = LinearSystem(A=A.astype(float), B=B.astype(float), U=tj.box_input_set(1.0, 3), W=Ball(6, 0.01))
    base = box_grid([0, 0, 0], [2, 1, 1], [2, 1, 1], labels={"1": ([0, 0, 0], [1, 1, 1]),
                                                             "2": ([1, 0, 0], [2, 1, 1])})
    return build_abstraction(lift_lookahead(base, [2, 1, 1]), system, zshape="cell", L_max=6, progress=False)


def test_algorithm1_in_6d_stays_in_its_tubes(tiny_ts):
    ts = tiny_ts
    assert ts.decomposition.dim == 6 and ts.n_edges >= 2
    plan = tj.plan(ts, [1, 2])
    rep = tj.simulate(ts, plan, runs=500, disturbance="adversarial", seed=3)
    assert rep.ok, rep.findings
    s = rep.summary
    assert s["tube_exits"] == 0 and s["obstacle_entries"] == 0 and s["workspace_exits"] == 0
    assert s["runs_reaching_all_targets"] == 500
    res = rep.result
    assert res.trajectories.shape[-1] == 6 and res.trajectories.dtype == np.float64
    assert np.all(res.violation <= 1e-9)          # every state inside its tube set, float64
    assert np.all(res.input_violation <= 1e-9)    # every input in U
    p, v = lookahead_to_velocity(res.trajectories, 2.0)
    # v+ - v = dt a + (w_s - w_p) / beta: |dv| <= dt |a|_max + sqrt(2) |w| / beta
    assert np.all(np.abs(np.diff(v, axis=1)) <= 0.5 + np.sqrt(2) * 0.01 / 2.0 + 1e-12)


def test_figures_draw_the_position_projection(tiny_ts):
    """The 3-D figures of a 6-D run are drawn over the map: tube sets as the hull of their positions."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tubejax.analyses.plot import drawn_space, figures_3d, plot_specification_layers

    ts = tiny_ts
    spec_plan = tj.plan(ts, [1, 2])
    plan = spec_plan.plan
    rep = tj.simulate(ts, spec_plan, runs=20, disturbance="adversarial", seed=1)
    base, axes, cell_of = drawn_space(ts.decomposition)
    assert base.dim == 3 and axes == (0, 2, 4) and len(cell_of) == ts.n_cells
    figs = dict(figures_3d(ts, plan, rep.result, plan.edges[0]))
    assert set(figs) == {"fig5_workspace", "fig6_tube", "fig7_trajectories", "fig9_tubes3d"}
    ax = figs["fig9_tubes3d"].axes[0]
    tubes = [c for c in ax.collections if c.get_zorder() == 3]
    assert len(tubes) == plan.cost
    lo, hi = np.array(ax.get_xlim3d()), np.array(ax.get_zlim3d())
    assert lo[0] >= 0 and lo[1] <= 2 and hi[1] <= 1                # the view is the map's, in positions
    plot_specification_layers(ts, spec_plan, rep.spec)
    plt.close("all")


def test_algorithm1_steers_along_product_tubes(tiny_ts):
    """The product path's edges (one scale per axis group) are simulated as the joint ones: in their tubes."""
    from tubejax.abstraction.product_abstraction import build_product_abstraction
    from tubejax.abstraction.product_transitions import product_transition_system
    from tubejax.analyses.control import SimulationRuns, simulate as simulate_plan

    joint = tiny_ts
    ps = build_product_abstraction(joint.decomposition, joint.system, zshape="cell", L_max=6)
    edges = ps.edge_dict()
    for e in joint.edges:                          # the product family contains the paper's
        assert edges[(e.src, e.dst)] <= e.L
    ts = product_transition_system(ps)
    assert ts.n_edges == ps.n_edges and len(ts.tubes) == ps.n_edges
    plan = tj.plan(ts, [1, 2]).plan
    assert any(np.ndim(ts.tubes[k].eps) == 2 for k in plan.edges)
    res = simulate_plan(ts, plan, SimulationRuns(n_runs=500, mode="adversarial", seed=5))
    s = res.summary()
    assert s["tube_exits"] == 0 and s["obstacle_entries"] == 0 and s["runs_reaching_all_targets"] == 500
    assert np.all(res.violation <= 1e-9) and np.all(res.input_violation <= 1e-9)
