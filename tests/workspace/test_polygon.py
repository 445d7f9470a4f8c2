"""Polygon workspaces: constrained triangulation, labels, order, obstacle case, errors."""

from pathlib import Path

import numpy as np
import pytest
import shapely
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from tubejax.model.workspace import (PolygonWorkspaceError, load_polygon_workspace,
                                     parse_polygon_workspace)
from tubejax.model.workspace.polygon import _Mesh

ROOMS = Path(__file__).resolve().parents[2] / "conf" / "workspace" / "maps" / "rooms.yaml"
L_SHAPE = [[0, 0], [4, 0], [4, 2], [2, 2], [2, 4], [0, 4]]


def free_space(data):
    free = shapely.Polygon(data["boundary"])
    for o in data.get("obstacles") or []:
        free = free.difference(shapely.Polygon(o))
    return free


def polys(dec):
    return [shapely.Polygon(c.vertices) for c in dec.cells]


def assert_valid_triangulation(dec, free, max_area=None):
    P = polys(dec)
    areas = np.array([p.area for p in P])
    assert all(c.n_vertices == 3 for c in dec.cells)
    assert np.all(areas >= 1e-12)
    assert areas.sum() == pytest.approx(free.area, rel=1e-9, abs=1e-9)
    if max_area is not None:
        assert areas.max() <= max_area * (1 + 1e-9)
    # every triangle inside the free space
    grown = free.buffer(1e-9)
    assert all(grown.covers(p) for p in P)
    # pairwise interiors disjoint
    iu, ju = np.triu_indices(len(P), k=1)
    arr = np.array(P, dtype=object)
    inter = shapely.area(shapely.intersection(arr[iu], arr[ju]))
    assert inter.max(initial=0.0) < 1e-9
    # conforming: no vertex in the relative interior of another triangle's edge
    V = np.unique(np.vstack([c.vertices for c in dec.cells]), axis=0)
    for c in dec.cells:
        for k in range(3):
            a, b = c.vertices[k], c.vertices[(k + 1) % 3]
            d = b - a
            s = (V - a) @ d / (d @ d)
            off = np.abs(d[0] * (V[:, 1] - a[1]) - d[1] * (V[:, 0] - a[0])) / np.linalg.norm(d)
            assert not np.any((s > 1e-9) & (s < 1 - 1e-9) & (off < 1e-9)), "T-junction"


@pytest.fixture(scope="module")
def rooms():
    return load_polygon_workspace(ROOMS)


@pytest.fixture(scope="module")
def rooms_data():
    return yaml.safe_load(ROOMS.read_text())


def test_rooms_triangulation(rooms, rooms_data):
    assert rooms.name == "rooms" and rooms.grid is None and rooms.dim == 2
    assert 40 <= rooms.n_cells <= 120
    assert_valid_triangulation(rooms, free_space(rooms_data), rooms_data["max_area"])


def test_rooms_is_nonconvex_with_nonconvex_obstacle(rooms_data):
    b = shapely.Polygon(rooms_data["boundary"])
    assert b.convex_hull.area > b.area + 1
    assert len(rooms_data["obstacles"]) == 2
    assert any(shapely.Polygon(o).convex_hull.area > shapely.Polygon(o).area + 1e-6
               for o in rooms_data["obstacles"])


def test_rooms_labels(rooms, rooms_data):
    free = free_space(rooms_data)
    regions = {str(k): shapely.Polygon(v) for k, v in rooms_data["regions"].items()}
    assert set(regions) == {"1", "2", "3"}
    for label, region in regions.items():
        ids = rooms.cells_with_label(label)
        assert ids
        union = shapely.union_all([shapely.Polygon(rooms.cells[i].vertices) for i in ids])
        # the region (within the free space) is exactly a union of triangles
        assert union.symmetric_difference(region.intersection(free)).area < 1e-9
    for c, lab in zip(rooms.cells, rooms.labels):
        inside = [k for k, r in regions.items() if r.contains(shapely.Point(c.centroid))]
        assert (inside[0] if inside else None) == lab


def test_order_is_deterministic_and_documented(rooms):
    again = load_polygon_workspace(ROOMS)
    assert again.n_cells == rooms.n_cells
    for a, b in zip(rooms.cells, again.cells):
        np.testing.assert_array_equal(a.vertices, b.vertices)
    assert again.labels == rooms.labels
    keys = [(-round(c.centroid[1], 9), round(c.centroid[0], 9)) for c in rooms.cells]
    assert keys == sorted(keys)


def test_notch_is_an_obstacle_case():
    dec = parse_polygon_workspace({"boundary": L_SHAPE, "max_area": 0.5}, "L.yaml")
    assert_valid_triangulation(dec, shapely.Polygon(L_SHAPE), 0.5)
    below = next(i for i, c in enumerate(dec.cells) if c.contains([3.5, 1.8]))
    left = next(i for i, c in enumerate(dec.cells) if c.contains([1.8, 3.5]))
    hull = shapely.Polygon(dec.pair_hull(below, left).vertices)
    assert hull.intersection(shapely.box(2, 2, 4, 4)).area > 0.1   # it crosses the notch
    M = dec.obstacle_case_matrix()
    assert M[below, left] and M[left, below]
    assert not M.diagonal().any()
    # a pair inside the convex bottom strip is free; the verdict matches shapely everywhere
    outside = shapely.box(-1, -1, 5, 5).difference(shapely.Polygon(L_SHAPE))
    for i in range(dec.n_cells):
        for j in range(i + 1, dec.n_cells):
            h = shapely.Polygon(dec.pair_hull(i, j).vertices)
            assert M[i, j] == (h.intersection(outside).area > 1e-9)
    assert (~M).sum() > dec.n_cells


def test_obstacles_are_obstacle_cases(rooms, rooms_data):
    obs = [shapely.Polygon(o) for o in rooms_data["obstacles"]]
    assert len(rooms.obstacles) == 3   # two obstacles and the outside of the boundary
    M = rooms.obstacle_case_matrix()
    i = next(k for k, c in enumerate(rooms.cells) if c.contains([1.5, 1.5]))
    j = next(k for k, c in enumerate(rooms.cells) if c.contains([3.5, 1.5]))
    assert shapely.Polygon(rooms.pair_hull(i, j).vertices).intersection(obs[0]).area > 0.1
    assert M[i, j]


def test_hole_and_touching_obstacle_and_no_refinement():
    data = {"boundary": [[0, 0], [6, 0], [6, 4], [0, 4]],
            "obstacles": [[[2, 1], [3, 1], [3, 3], [2, 3]],                # a hole
                          [[5, 0], [6, 0], [6, 2], [5.5, 1], [5, 2]]],     # touches the boundary
            "regions": {"g": [[0, 0], [1.5, 0], [1.5, 4], [0, 4]]}}
    dec = parse_polygon_workspace(data, "h.yaml")
    assert dec.name == "h.yaml"
    assert_valid_triangulation(dec, free_space(data))
    g = shapely.union_all([shapely.Polygon(dec.cells[i].vertices) for i in dec.cells_with_label("g")])
    assert g.area == pytest.approx(6.0)


def test_sliver_repair_keeps_mesh_conforming():
    m = _Mesh()
    a, b, c, d = (m.vertex(p) for p in [(0, 0), (2, 0), (1, 0), (1, 1)])
    m.add((a, c, b))   # zero area: c lies on edge ab
    m.add((a, b, d))
    m.add((a, c, m.vertex((1, -1))))
    m.drop_slivers()
    tris = sorted(tuple(sorted(m.pts[v] for v in t)) for t in m.tris.values())
    assert tris == sorted([((0, 0), (1, 0), (1, 1)), ((1, 0), (1, 1), (2, 0)),
                           ((0, 0), (1, -1), (1, 0))])


@settings(max_examples=25, deadline=None)
@given(st.floats(0.5, 3.5), st.floats(0.5, 2.5), st.floats(0.2, 1.0), st.floats(0.3, 2.0))
def test_random_box_workspaces(ox, oy, size, max_area):
    data = {"boundary": [[0, 0], [5, 0], [5, 4], [0, 4]],
            "obstacles": [[[ox, oy], [ox + size, oy], [ox + size / 2, oy + size]]],
            "regions": {"A": [[0, 0], [1.3, 0], [1.3, 1.1], [0, 1.1]]},
            "max_area": max_area}
    dec = parse_polygon_workspace(data, "rand.yaml")
    assert_valid_triangulation(dec, free_space(data), max_area)


GOOD = {"boundary": [[0, 0], [4, 0], [4, 4], [0, 4]]}


@pytest.mark.parametrize("change, field", [
    ({"boundary": None}, "'boundary'"),
    ({"boundary": [[0, 0], [1, 1], [1, 0], [0, 1]]}, "'boundary'"),     # bow tie
    ({"boundary": [[0, 0], [1, 0]]}, "'boundary'"),
    ({"boundary": [[0, 0], [1, 0], [2, 0]]}, "'boundary'"),             # zero area
    ({"boundary": [[0, 0], ["a", 0], [1, 1]]}, "'boundary'"),
    ({"boundary": [[0, 0], [1, 0, 3], [1, 1]]}, "'boundary'"),
    ({"boundary": [[0, 0], [True, 0], [1, 1]]}, "'boundary'"),
    ({"boundary": [[0, 0], [float("nan"), 0], [1, 1]]}, "'boundary'"),
    ({"obstacles": [[[5, 5], [6, 5], [6, 6]]]}, "'obstacles[0]'"),      # outside
    ({"obstacles": [[[3, 1], [5, 1], [5, 2]]]}, "'obstacles[0]'"),      # partly outside
    ({"obstacles": [[[1, 1], [2, 1], [2, "x"]]]}, "'obstacles[0]'"),
    ({"obstacles": [[[-1, -1], [5, -1], [5, 5], [-1, 5]]]}, "'obstacles[0]'"),
    ({"obstacles": [[[0, 0], [4, 0], [4, 4], [0, 4]]]}, "'obstacles'"),   # nothing free
    ({"obstacles": {"a": 1}}, "'obstacles'"),
    ({"regions": [[0, 0], [1, 0], [1, 1]]}, "'regions'"),
    ({"regions": {"A": [[0, 0], [2, 0], [2, 2]], "B": [[1, 0], [3, 0], [3, 2]]}}, "regions['B']"),
    ({"regions": {"A": [[5, 5], [6, 5], [6, 6]]}}, "regions['A']"),
    ({"regions": {1: [[0, 0], [1, 0], [1, 1]], "1": [[2, 2], [3, 2], [3, 3]]}}, "regions['1']"),
    ({"max_area": 0}, "'max_area'"),
    ({"max_area": -1.0}, "'max_area'"),
    ({"max_area": "big"}, "'max_area'"),
    ({"max_area": True}, "'max_area'"),
    ({"max_area": float("inf")}, "'max_area'"),
    ({"max_area": 1e-9}, "'max_area'"),
    ({"nmae": "typo"}, "'nmae'"),
])
def test_bad_input_names_file_and_field(change, field):
    data = {**GOOD, **change}
    if change.get("boundary", 0) is None:
        del data["boundary"]
    with pytest.raises(PolygonWorkspaceError, match="bad.yaml") as info:
        parse_polygon_workspace(data, "bad.yaml")
    assert field in str(info.value)


def test_not_a_mapping():
    with pytest.raises(PolygonWorkspaceError, match="x.yaml: expected a mapping"):
        parse_polygon_workspace([1, 2], "x.yaml")


def test_load_errors(tmp_path):
    bad = tmp_path / "broken.yaml"
    bad.write_text("boundary: [[0, 0], [1, 0]\nmax_area: 1\n")
    with pytest.raises(PolygonWorkspaceError, match=r"broken\.yaml, line \d+, column \d+: invalid YAML"):
        load_polygon_workspace(bad)
    empty = tmp_path / "empty.yaml"
    empty.write_text("")
    with pytest.raises(PolygonWorkspaceError, match="empty.yaml: the file is empty"):
        load_polygon_workspace(empty)
    with pytest.raises(PolygonWorkspaceError, match="missing.yaml: cannot read"):
        load_polygon_workspace(tmp_path / "missing.yaml")
    nob = tmp_path / "nob.yaml"
    nob.write_text("name: x\nobstacles: []\n")
    with pytest.raises(PolygonWorkspaceError, match=r"nob\.yaml: field 'boundary': missing"):
        load_polygon_workspace(nob)


def test_duplicate_key_names_the_key_and_line(tmp_path):
    p = tmp_path / "dup.yaml"
    p.write_text("boundary: [[0, 0], [4, 0], [4, 4], [0, 4]]\n"
                 "regions:\n  A: [[0, 0], [1, 0], [1, 1], [0, 1]]\n  A: [[3, 3], [4, 3], [4, 4], [3, 4]]\n")
    with pytest.raises(PolygonWorkspaceError, match=r"dup\.yaml, line 4, column 3: invalid YAML \(duplicate key "
                                                    r"'A' \(first at line 3\)\)"):
        load_polygon_workspace(p)
    p.write_text("boundary: [[0, 0], [4, 0], [4, 4], [0, 4]]\nmax_area: 1\nmax_area: 2\n")
    with pytest.raises(PolygonWorkspaceError, match=r"line 3, column 1: invalid YAML \(duplicate key 'max_area'"):
        load_polygon_workspace(p)


def test_non_utf8_polygon_file_names_the_file(tmp_path):
    p = tmp_path / "w.yaml"
    p.write_bytes(b"name: caf\xe9\nboundary: [[0, 0], [1, 0], [0, 1]]\n")
    with pytest.raises(PolygonWorkspaceError, match=r"w\.yaml, line 1, column 10: not valid UTF-8"):
        load_polygon_workspace(p)


@pytest.mark.parametrize("point, match", [
    ([10 ** 400, 0], "not finite"),
    ([1e7, 0], r"out of range \(expected \|x\|, \|y\| <= 1e\+06\)"),
])
def test_coordinates_out_of_range(point, match):
    with pytest.raises(PolygonWorkspaceError, match=match):
        parse_polygon_workspace({"boundary": [[0, 0], point, [0, 1]]}, name="w")
