"""Findings of the property tests, shrunk to regression tests (they were strict xfails until fixed)."""

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from property_cases import check_edge  # noqa: E402
from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.analyses.control import SimulationRuns, simulate_edge  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.model.system import LinearSystem, one_norm_input_set  # noqa: E402
from tubejax.model.workspace import PolygonWorkspaceError, box_grid, parse_polygon_workspace  # noqa: E402


def test_unaligned_obstacle_box_workspace_exit():
    # found by test_controller_keeps_states_in_the_tube with unaligned obstacles (shrunk by hand):
    # box_grid keeps the small box as the obstacle but removes the whole cell (0, 0); a state in
    # the rest of that cell is free space inside the workspace, and was counted as a workspace
    # exit (a false alarm). The box grid's decomposition now knows its box (``domain``).
    d = box_grid([0, 0], [2, 2], [2, 2], obstacles=[([0.0, 0.0], [0.3, 0.3])])   # removes cell (0, 0)
    c, s = np.cos(0.5), np.sin(0.5)
    sysm = LinearSystem(A=np.array([[c, -s], [s, c]]), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2),
                        W=Ball(2, 0.0))
    ts = build_abstraction(d, sysm, L_max=2, progress=False)
    k = [(e.src, e.dst) for e in ts.edges].index((1, 0))        # (1, 0) -> (0, 1): free case
    assert not d.obstacle_case(1, 0)
    check_edge(ts, k)
    s = simulate_edge(ts, k, SimulationRuns(n_runs=64, seed=0)).summary()
    assert s["obstacle_entries"] == 0 and s["tube_exits"] == 0    # safe, in the tube ...
    assert s["workspace_exits"] == 0, s                           # ... and inside the workspace


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
