"""workspace.velocity_divisions: a grid/voxel map lifted to look-ahead state space (docs/math/drone.md).

Checked against an independent construction: the same cells as a 6-D box grid over the map's
extent in every coordinate (voxel lines in the positions, look-ahead slabs in the s axes) with
every map obstacle extended over all look-aheads.
"""

from pathlib import Path

import numpy as np
import pytest

from tubejax.errors import InputModelError
from tubejax.inputs import ProblemInputs
from tubejax.model.workspace import box_grid
from tubejax.model.workspace.lookahead import VelocityDivisionsError, lift_lookahead, position_view
from tubejax.model.workspace.voxelmap import load_map

ROOT = Path(__file__).resolve().parents[2]
BUILDING = ROOT / "conf" / "workspace" / "maps" / "building3d.txt"
DIV = (2, 1, 3)


@pytest.fixture(scope="module")
def building():
    return load_map(BUILDING)


@pytest.fixture(scope="module")
def lifted(building):
    return lift_lookahead(building, DIV)


def _key(lo, hi):
    return tuple(np.round(np.concatenate([lo, hi]), 12))


def test_cells_match_a_6d_box_grid_minus_lifted_obstacles(building, lifted):
    (x0, y0, z0), (x1, y1, z1) = building.domain.bounding_box()
    lo6 = [x0, x0, y0, y0, z0, z0]
    hi6 = [x1, x1, y1, y1, z1, z1]
    divisions = [int(x1 - x0), DIV[0], int(y1 - y0), DIV[1], int(z1 - z0), DIV[2]]
    obstacles = []
    for o in building.obstacles:                     # the map's obstacle boxes, every look-ahead
        a, b = o.bounding_box()
        obstacles.append(([a[0], x0, a[1], y0, a[2], z0], [b[0], x1, b[1], y1, b[2], z1]))
    ref = box_grid(lo6, hi6, divisions, obstacles=obstacles)
    assert lifted.dim == 6
    assert lifted.n_cells == building.n_cells * int(np.prod(DIV)) == ref.n_cells
    got = {_key(*P.bounding_box()) for P in lifted.cells}
    want = {_key(*P.bounding_box()) for P in ref.cells}
    assert got == want
    assert all(P.n_vertices == 64 for P in lifted.cells[:5])
    np.testing.assert_array_equal(np.array(lifted.domain.bounding_box()), np.array([lo6, hi6], float))


def test_labels_grid_and_position_view_are_the_maps(building, lifted):
    view = position_view(lifted)
    assert view is not None and view.axes == (0, 2, 4) and view.base is building
    per = int(np.prod(DIV))
    for i in range(0, lifted.n_cells, 7):
        b = i // per
        assert view.base_cell[i] == b
        assert lifted.labels[i] == building.labels[b]
        lo, hi = lifted.cells[i].bounding_box()
        blo, bhi = building.cells[b].bounding_box()
        np.testing.assert_array_equal(lo[[0, 2, 4]], blo)
        np.testing.assert_array_equal(hi[[0, 2, 4]], bhi)
        np.testing.assert_array_equal(lifted.grid[i], list(building.grid[b]) + list(np.unravel_index(i % per, DIV)))
    for label in ("1", "2"):
        assert len(lifted.cells_with_label(label)) == per * len(building.cells_with_label(label))


def test_obstacle_case_is_the_maps_on_position_projection(building, lifted):
    """A pair's safe set meets a lifted obstacle exactly when the voxel pair's hull meets a map obstacle."""
    rng = np.random.default_rng(0)
    per = int(np.prod(DIV))
    src = rng.integers(0, lifted.n_cells, 60)
    grid = np.asarray(building.grid)
    dst = []
    for s in src:                                  # a voxel within two steps, any look-ahead slab
        near = np.flatnonzero(np.abs(grid - grid[s // per]).max(axis=1) <= 2)
        dst.append(rng.choice(near) * per + rng.integers(0, per))
    dst = np.array(dst)
    got = lifted.obstacle_cases(src, dst)
    want = building.obstacle_cases(src // per, dst // per)
    np.testing.assert_array_equal(got, want)
    assert want.any() and not want.all()


@pytest.mark.parametrize("bad", [0, -1, [2, 2], [1, 0, 1], "2", 2.5, True, [True, 1, 1]])
def test_bad_velocity_divisions_are_refused_naming_the_field(bad):
    data = {"workspace": {"kind": "grid", "map_file": str(BUILDING), "velocity_divisions": bad},
            "system": {"kind": "double_integrator", "axes": 3, "dt": 0.5, "beta": 2.0,
                       "U": {"kind": "box", "bound": 1.0}},
            "disturbance": {"kind": "ball", "radius": 0.01}}
    with pytest.raises(InputModelError) as exc:
        ProblemInputs.from_dict(data)
    assert "workspace.velocity_divisions" in str(exc.value)


def test_the_system_must_match_the_lifted_dimension():
    data = {"workspace": {"kind": "grid", "map_file": str(BUILDING), "velocity_divisions": 2},
            "system": {"kind": "double_integrator", "axes": 2, "dt": 0.5, "beta": 2.0,
                       "U": {"kind": "box", "bound": 1.0}},
            "disturbance": {"kind": "ball", "radius": 0.01}}
    with pytest.raises(InputModelError, match="6-D"):
        ProblemInputs.from_dict(data)
    data["system"]["axes"] = 3
    d = ProblemInputs.from_dict(data).workspace.build()
    assert d.dim == 6 and d.n_cells == 8 * load_map(BUILDING).n_cells


def test_a_map_of_non_boxes_is_refused():
    from tubejax.model.workspace.polygon import parse_polygon_workspace_text

    tri = parse_polygon_workspace_text("boundary: [[0, 0], [2, 0], [0, 2]]\n", name="tri.yaml")
    with pytest.raises(VelocityDivisionsError, match="not a box"):
        lift_lookahead(tri, 2)


def test_a_2d_map_lifts_to_4d_like_boxgrid4d():
    """The 2x2 map with one obstacle square and unit look-ahead slabs over [0, 2] is conf/workspace/boxgrid4d."""
    from tubejax.model.workspace.gridmap import parse_grid_map

    base = parse_grid_map("1#\n.2\n", name="l.txt")
    lifted = lift_lookahead(base, 2)
    ref = box_grid([0, 0, 0, 0], [2, 2, 2, 2], [2, 2, 2, 2], obstacles=[([1, 0, 1, 0], [2, 2, 2, 2])])
    assert {_key(*P.bounding_box()) for P in lifted.cells} == {_key(*P.bounding_box()) for P in ref.cells}
    assert lifted.n_cells == 12 and lifted.labels.count("1") == 4 and lifted.labels.count("2") == 4
