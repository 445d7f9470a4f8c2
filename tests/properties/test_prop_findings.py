"""Findings of the property tests, shrunk to regression tests (they were strict xfails until fixed)."""

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from property_cases import check_edge  # noqa: E402
from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.control import simulate_edge  # noqa: E402
from tubejax.geometry import Ball  # noqa: E402
from tubejax.system import LinearSystem, one_norm_input_set  # noqa: E402
from tubejax.workspace import PolygonWorkspaceError, box_grid, parse_polygon_workspace  # noqa: E402


def test_unaligned_obstacle_box_leaves_no_uncovered_free_space():
    # found by test_controller_keeps_states_in_the_tube with unaligned obstacles (shrunk by hand):
    # box_grid used to keep the small box as the obstacle while removing the whole cell (0, 0),
    # so a state in the rest of that cell counted as a workspace exit (a false alarm). The
    # obstacle now grows to the cells it removes.
    d = box_grid([0, 0], [2, 2], [2, 2], obstacles=[([0.0, 0.0], [0.3, 0.3])])   # removes cell (0, 0)
    lo, hi = d.obstacles[0].bounding_box()
    assert np.allclose(lo, [0, 0]) and np.allclose(hi, [1, 1])
    c, s = np.cos(0.5), np.sin(0.5)
    sysm = LinearSystem(np.array([[c, -s], [s, c]]), 0.5 * np.eye(2), one_norm_input_set(1.0, 2),
                        Ball(2, 0.0))
    ts = build_abstraction(d, sysm, L_max=2, progress=False)
    assert d.obstacle_case(1, 0)                      # P_ij of (1, 0) -> (0, 1) crosses cell (0, 0)
    for k in range(len(ts.edges)):
        check_edge(ts, k)
        s = simulate_edge(ts, k, n_runs=64, seed=0).summary()
        assert s["obstacle_entries"] == 0 and s["tube_exits"] == 0, s
        assert s["workspace_exits"] == 0, s


def test_polygon_with_a_tiny_edge_is_decomposed_or_refused_clearly():
    # found by test_pruning_drops_only_infeasible_horizons[tri] (campaign, 500 examples)
    data = {"boundary": [[1.0, 0.0], [0.30901699437494745, 0.9510565162951535],
                         [-0.8090169943749473, 0.5877852522924732],
                         [-0.8090169943749476, -0.587785252292473], [1.0, -2.4492935982947064e-16]]}
    try:
        d = parse_polygon_workspace(data)
    except PolygonWorkspaceError as err:
        assert "boundary" in str(err) and "qhull" not in str(err).lower()
        return
    assert all(P.n_vertices == 3 for P in d.cells)
