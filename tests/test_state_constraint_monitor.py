"""The closed-loop monitor and the figures read ``system.state_constraints`` generically
(here the state constraint ``X``)."""

from types import SimpleNamespace

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from tubejax.analyses.control.simulate import summary_violations  # noqa: E402
from tubejax.analyses.control.state_monitor import (count_outside_state_constraints,  # noqa: E402
                                                        outside_state_constraint, state_constraint_violation)
from tubejax.analyses.plot import RunsStyle, new_axes, plot_trajectories, plot_workspace, save_figure  # noqa: E402
from tubejax.analyses.plot.constraint_layer import plot_state_constraints  # noqa: E402
from tubejax.model.geometry import Ball, Halfspaces  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace.gridmap import load_grid_map  # noqa: E402
from tubejax.analyses.control import SimulationRuns  # noqa: E402


@pytest.fixture
def with_x():
    def make(X=None):
        return LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2), X=X)

    return make


@pytest.fixture(scope="module")
def line_map(tmp_path_factory):
    p = tmp_path_factory.mktemp("map") / "line.txt"
    p.write_text("1..2\n")                                   # four unit cells, x in [0, 4], y in [0, 1]
    return load_grid_map(p)


def test_the_system_lists_x_when_set(with_x):
    X = Halfspaces([[1.0, 0.0]], [2.5], "system.X")
    assert with_x(X).state_constraints == {"X": X}
    assert with_x().state_constraints == {}


def test_hand_made_count():
    # rows of norm 2 and 3: x_1 <= 1, x_2 >= -1 (the violation is a distance)
    S = Halfspaces([[2.0, 0.0], [0.0, -3.0]], [2.0, 3.0], "system.X")
    traj = np.array([[[0.0, 0.0], [1.0, 0.0], [1.0 + 5e-10, 0.0], [1.5, 0.0], [0.0, -1.5]],     # 2 outside
                     [[0.0, 0.0], [np.nan, 0.0], [1.0 + 2e-9, -1.0], [0.5, 0.5], [0.5, -0.9]]])  # 2 outside
    v = state_constraint_violation(S, traj)
    assert v.shape == (2, 5) and v.dtype == np.float64
    finite = np.isfinite(v)
    np.testing.assert_allclose(v[finite], S.violation(traj)[finite], rtol=0, atol=1e-15)
    np.testing.assert_allclose(v[0], [-1.0, 0.0, 5e-10, 0.5, 0.5], rtol=1e-6, atol=1e-15)
    out = outside_state_constraint(S, traj, tol=1e-9)
    assert out.tolist() == [[False, False, False, True, True], [False, True, True, False, False]]
    counts = count_outside_state_constraints({"X": S}, traj, tol=1e-9)
    assert list(counts) == ["X"] and counts["X"].tolist() == [2, 2]
    assert count_outside_state_constraints({"X": S}, traj, tol=0.0)["X"].tolist() == [3, 2]
    assert count_outside_state_constraints({}, traj) == {}


def test_simulation_reports_states_outside(with_x, line_map):
    from tubejax.abstraction import build_abstraction
    from tubejax.analyses.control import plan_controller, plan_sequence, simulate

    d = line_map
    ts = build_abstraction(d, with_x(), L_max=10, progress=False)
    plan = plan_sequence(ts, d.cells_with_label("1")[0], ["2"])
    ctrl = plan_controller(ts, plan, jax.numpy.float64)
    X = Halfspaces([[1.0, 0.0]], [2.5], "system.X")           # the plan ends in x_1 in [3, 4]: outside X
    res = simulate(SimpleNamespace(decomposition=d, system=with_x(X)), plan, SimulationRuns(n_runs=6), ctrl=ctrl)
    expected = ~(X.violation(res.trajectories) <= res.tol)
    s = res.summary()
    assert s["outside_state_constraints"] == {"X": int(expected.sum())} and expected.sum() > 0
    assert res.state_constraint_exit.tolist() == expected.any(1).tolist()
    assert s["tube_exits"] == 0 and s["obstacle_entries"] == 0
    assert any("outside the state constraint X" in b for b in summary_violations(s))
    plain = simulate(SimpleNamespace(decomposition=d, system=with_x()), plan, SimulationRuns(n_runs=6), ctrl=ctrl)
    assert plain.summary()["outside_state_constraints"] == {} and summary_violations(plain.summary()) == []
    assert not plain.state_constraint_exit.any()
    np.testing.assert_array_equal(plain.trajectories, res.trajectories)      # the monitor changes no run


def _texts(ax):
    return {t.get_text() for t in ax.texts}


def test_figures_with_and_without_x(line_map, tmp_path):
    d = line_map
    X = Halfspaces([[1.0, 0.0], [0.0, 1.0]], [2.5, 0.8], "system.X")        # unbounded: x_1 <= 2.5, x_2 <= 0.8
    fig, ax = new_axes()
    plot_workspace(d, ax, state_constraints={"X": X})
    assert "outside X" in _texts(ax)
    assert ax.get_xlim()[1] < 4.5                                         # the view is kept
    png, pdf = save_figure(fig, tmp_path, "ws_with_x")
    assert png.is_file() and pdf.is_file()
    plt.close(fig)
    fig, ax = new_axes()
    plot_workspace(d, ax)
    assert "outside X" not in _texts(ax)
    assert all(p.is_file() for p in save_figure(fig, tmp_path, "ws_without_x"))
    plt.close(fig)

    traj = np.array([[[0.5, 0.5], [1.5, 0.5], [3.5, 0.5]], [[0.5, 0.2], [1.5, 0.2], [2.0, 0.2]]])
    for cons, flag in (({"X": X}, [True, False]), ({}, [False, False])):
        res = SimpleNamespace(trajectories=traj, state_constraints=cons, state_constraint_exit=np.array(flag),
                              seed=0)
        fig, ax = new_axes()
        plot_trajectories(d, res, ax, RunsStyle(max_runs=None))
        assert ("outside X" in _texts(ax)) == bool(cons)
        legend = [t.get_text() for t in ax.get_legend().get_texts()]
        assert ("violating run" in legend) == bool(cons)                  # the run outside X is drawn red
        assert all(p.is_file() for p in save_figure(fig, tmp_path, f"traj_{len(cons)}"))
        plt.close(fig)


def test_figure_dimensions():
    fig, ax = new_axes()
    ax.set_xlim(0, 4)
    ax.set_ylim(0, 1)
    box = Halfspaces(np.vstack([np.eye(2), -np.eye(2)]), [3.0, 0.9, -1.0, -0.1], "system.X")   # bounded, in view
    in3 = Halfspaces([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], [2.0, 1.0], "system.X")               # one planar row
    off3 = Halfspaces([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]], [1.0, 1.0], "system.X")              # none planar
    one = Halfspaces([[1.0]], [0.5], "system.X")
    far = Halfspaces([[1.0, 0.0]], [10.0], "system.X")                                         # the view is inside
    assert plot_state_constraints(ax, {"B": box, "C": in3, "D": off3, "E": one, "F": far}) == ["B", "C"]
    assert ax.get_xlim() == (0.0, 4.0) and ax.get_ylim() == (0.0, 1.0)
    plt.close(fig)
