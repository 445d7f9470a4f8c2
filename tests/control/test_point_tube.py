"""Point tubes (``eps_l = 0``, W = {0}) are followed; a NaN state counts as a tube exit.

Found by the property tests (tests/properties): with ``W = Ball(n, 0)`` HiGHS returns tubes
with ``eps = 0`` (valid: ``Q_l = {p_l}``); the controller divided by ``eps`` and every run
became NaN, reported as workspace exits but not as tube exits (``NaN > tol`` is False).
"""

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.analyses.control import SimulationRuns, plan_controller, plan_edge, simulate, simulate_edge  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace import box_grid  # noqa: E402


@pytest.fixture(scope="module")
def point_tubes():
    d = box_grid([0.0, 0.0], [3.0, 1.0], [3, 1])
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.0))
    ts = build_abstraction(d, s, L_max=3, progress=False)
    ts.verify()
    return ts


@pytest.mark.parametrize("mode", ["uniform", "adversarial", "none"])
def test_point_tubes_are_followed(point_tubes, mode):
    ts = point_tubes
    ks = [k for k, t in enumerate(ts.tubes) if np.any(np.abs(t.eps) == 0.0)]
    assert ks, "HiGHS gave no point tube here: the regression is not exercised"
    for k in ks:
        s = simulate_edge(ts, k, SimulationRuns(n_runs=40, mode=mode, seed=k)).summary()
        assert (s["tube_exits"], s["workspace_exits"], s["obstacle_entries"]) == (0, 0, 0), s
        assert s["runs_reaching_all_targets"] == 40, s
        assert s["max_tube_violation"] <= 1e-9 and s["max_input_violation"] <= 1e-9, s


def test_nan_state_is_a_tube_exit(point_tubes):
    ts = point_tubes
    plan = plan_edge(ts, 0)
    with jax.enable_x64(True):
        ctrl = plan_controller(ts, plan, jax.numpy.float64)
    bad = ctrl._replace(u=ctrl.u * np.nan)
    res = simulate(ts, plan, SimulationRuns(n_runs=10), ctrl=bad)
    assert np.all(res.tube_exit) and np.all(res.first_exit_time == 1)
