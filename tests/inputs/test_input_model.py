"""The typed input model (issue 11, "what must exist" 2; findings 5 and 7) and its provenance record."""

import copy
import json
from pathlib import Path

import numpy as np
import pytest

from tubejax.errors import InputError, InputModelError
from tubejax.model.geometry import Ball, Polytope
from tubejax.inputs import ProblemInputs, SpecSettings, from_record, validate_section
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import box_grid, load_grid_map, load_polygon_workspace

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / "tests" / "data" / "tiny.txt"


def base() -> dict:
    return {
        "workspace": {"kind": "grid", "map_file": str(TINY)},
        "system": {"name": "integrator2d", "A": [[1.0, 0.0], [0.0, 1.0]], "B": [[0.5, 0.0], [0.0, 0.5]],
                   "U": {"kind": "box", "bound": 1.0}},
        "disturbance": {"kind": "ball", "radius": 0.2},
        "zshape": {"kind": "box", "scale": 1.0},
        "abstraction": {"L_max": 10, "eps_min": 0.0, "pruning": True, "method": "tube", "seed": 0,
                        "verify": "none", "solver": {"name": "pdhg", "pool": 64, "dtype": "float64"}},
        "simulation": {"runs": 50, "mode": "uniform", "seed": 0},
        "spec": {"sequence": [1, 2], "start_cell": None, "planner": "exact"},
    }


def with_value(path: str, value) -> dict:
    d = base()
    *head, last = path.split(".")
    cur = d
    for k in head:
        cur = cur[k]
    cur[last] = value
    return d


def refused(data) -> InputModelError:
    with pytest.raises(InputModelError) as info:
        ProblemInputs.from_dict(data)
    return info.value


def test_valid_inputs_build_the_same_objects_as_the_library():
    m = ProblemInputs.from_dict(base())
    d = m.build_decomposition()
    ref = load_grid_map(TINY)
    assert d.n_cells == ref.n_cells and d.labels == ref.labels and np.array_equal(d.grid, ref.grid)
    s = m.build_system()
    expect = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    assert np.array_equal(s.A, expect.A) and np.array_equal(s.B, expect.B) and s.W == expect.W
    assert np.array_equal(s.U.vertices, expect.U.vertices)
    assert m.abstraction_kwargs() == {"zshape": "box", "z_scale": 1.0, "L_max": 10, "eps_min": 0.0, "min_margin": 0.0,
                                      "pruning": True, "method": "tube"}
    assert m.abstraction.solver.options()["pool"] == 64 and m.abstraction.solver.options()["dtype"] == "float64"
    assert m.spec.labels == ["1", "2"]


def test_other_sources_and_sets_build():
    rooms_file = "conf/workspace/maps/rooms.yaml"
    rooms = ProblemInputs.from_dict({**base(), "workspace": {"kind": "polygon", "file": rooms_file},
                                     "zshape": {"kind": "regular"}}, search_dirs=[ROOT])
    assert rooms.build_decomposition().n_cells == load_polygon_workspace(ROOT / rooms_file).n_cells
    grid4 = {"kind": "boxgrid", "lower": [0, 0, 0, 0], "upper": [2, 2, 2, 2], "divisions": [2, 2, 2, 2],
             "obstacles": [[[1, 0, 1, 0], [2, 2, 2, 2]]], "labels": {1: [[0, 0, 1, 0], [1, 2, 2, 2]]}}
    m = ProblemInputs.from_dict({**base(), "workspace": grid4,
                                 "system": {"A": np.eye(4).tolist(), "B": np.eye(4)[:, :2].tolist(),
                                            "U": {"kind": "one_norm", "radius": 1}},
                                 "disturbance": {"kind": "polytope",
                                                 "vertices": (0.01 * np.vstack([np.eye(4), -np.eye(4)])).tolist()}})
    d = m.build_decomposition()
    ref = box_grid([0] * 4, [2] * 4, [2] * 4, obstacles=[([1, 0, 1, 0], [2, 2, 2, 2])],
                   labels={"1": ([0, 0, 1, 0], [1, 2, 2, 2])})
    assert d.n_cells == ref.n_cells == 12 and d.labels == ref.labels
    assert isinstance(m.build_system().W, Polytope) and m.build_system().U.n_vertices == 4


@pytest.mark.parametrize("path, value, field, words", [
    # finding 5: silently wrong abstractions from bad numbers
    ("zshape.scale", 1e9, "zshape.scale", "in [0.001, 1000] (with eps_min = 0 only the shape of Z decides feasibility"),
    ("zshape.scale", 1e-9, "zshape.scale", "in [0.001, 1000]"),
    ("zshape.scale", float("nan"), "zshape.scale", "a finite number"),
    ("abstraction.eps_min", float("nan"), "abstraction.eps_min", "a finite number in [0, 1000], got nan"),
    ("system.U.bound", float("nan"), "system.U.bound", "a finite number in (0, 1e6]"),
    ("system.U.bound", float("inf"), "system.U.bound", "got inf"),
    ("abstraction.L_max", True, "abstraction.L_max", "an integer in [1, 1000], got True"),
    ("abstraction.pruning", "maybe", "abstraction.pruning", "true or false, got 'maybe'"),
    ("simulation.runs", 2.5, "simulation.runs", "an integer in [1, 10000000], got 2.5"),
    # finding 7: tracebacks and unnamed fields
    ("simulation.runs", "abc", "simulation.runs", "got 'abc'"),
    ("system.A", 1.0, "system.A", "a square matrix (a list of n rows of n numbers), finite with |x| <= 1e6, got 1.0"),
    ("disturbance.radius", [0.1, 0.2], "disturbance.radius", "a finite number in [0, 1e6], got [0.1, 0.2]"),
    ("disturbance.radius", "big", "disturbance.radius", "got 'big'"),
    ("spec.sequence", 5, "spec.sequence", "a list of 1 to 1000 region labels"),
    # more of the same classes
    ("abstraction.method", "magic", "abstraction.method", "one of tube, openloop, exact2d, got 'magic'"),
    ("abstraction.verify", "some", "abstraction.verify", "one of none, all"),
    ("abstraction.seed", -1, "abstraction.seed", "an integer in [0, 4294967295]"),
    ("abstraction.solver.pool", 100, "abstraction.solver.pool", "a power of two, got 100"),
    ("abstraction.solver.name", "cplex", "abstraction.solver.name", "one of highs, pdhg, got 'cplex'"),
    ("abstraction.solver.ruiz_iters", "sometimes", "abstraction.solver.ruiz_iters",
     "an integer in [0, 100] or one of auto, got 'sometimes'"),
    ("abstraction.solver.ruiz_iters", -1, "abstraction.solver.ruiz_iters", "an integer in [0, 100] or one of auto"),
    ("simulation.mode", "wild", "simulation.mode", "one of uniform, boundary, adversarial, none"),
    ("spec.sequence", [1, True], "spec.sequence[1]", "a region label"),
    ("spec.planner", "fast", "spec.planner", "one of exact, greedy"),
    ("system.A", [[1, 0], [0]], "system.A", "rows of equal length"),
    ("system.A", [[1, 0, 0], [0, 1, 0]], "system.A", "square matrix, got 2 rows of 3 numbers"),
    ("system.B", [[0.5, 0], [0, 0.5], [1, 1]], "system.B", "expected 2 rows"),
    ("system.U.bound", [1, 2, 3], "system.U.bound", "one number or 2"),
    ("system.U", {"kind": "polytope", "vertices": [[0, 0], [1, 1], [-1, -1]]}, "system.U.vertices",
     "U must have volume: the 3 points do not span R^2"),
    ("system.U", {"kind": "polytope", "vertices": [[0, 0], [1, 0], [0, 1]]}, "system.U.vertices",
     "U must contain 0 in its interior"),
    ("disturbance", {"kind": "box", "half_width": float("nan")}, "disturbance.half_width", "got nan"),
    ("disturbance", {"kind": "polytope", "vertices": [[0, 0], [1, 1], [2, 2]]}, "disturbance.vertices",
     "W must have volume"),
    ("disturbance", {"kind": "polytope", "vertices": [[0.1, 0.1], [1, 0.1], [0.1, 1]]}, "disturbance.vertices",
     "W must contain 0"),
    ("disturbance", {"kind": "cube"}, "disturbance.kind", "one of ball, box, polytope, got 'cube'"),
    ("disturbance", {"radius": 0.1}, "disturbance.kind", "missing (expected one of ball, box, polytope)"),
    ("disturbance", {"kind": "ball", "radius": 0.1, "raduis": 0.2}, "disturbance.raduis", "unknown field"),
    ("disturbance", {"kind": "polytope", "vertices": [[0.1, 0, 0], [0, 0.1, 0], [-0.1, -0.1, 0.1], [0, 0, -0.1]]},
     "disturbance.vertices", "expected points in R^2"),
    ("workspace.map_file", "/nonexistent/map.txt", "workspace.map_file", "file '/nonexistent/map.txt' not found"),
    ("workspace.map_file", str(ROOT / "conf"), "workspace.map_file", "expected a file, got the directory"),
    ("zshape.kind", "star", "zshape.kind", "one of box, diamond, cell, regular"),
])
def test_every_bad_value_is_refused_with_field_value_and_expectation(path, value, field, words):
    err = refused(with_value(path, value))
    assert isinstance(err, InputError) and isinstance(err, ValueError)
    assert err.problems[0][0] == field
    assert words in err.problems[0][1]
    assert str(err).startswith(f"{field}: ")


def test_dimensions_must_agree():
    d = base()
    d["system"] = {"A": np.eye(3).tolist(), "B": np.eye(3).tolist(), "U": {"kind": "box", "bound": 1}}
    assert "a 2 x 2 matrix (the workspace is 2-D), got 3 x 3" in str(refused(d))
    d = base()
    d["workspace"] = {"kind": "boxgrid", "lower": [0, 0, 0], "upper": [1, 1, 1], "divisions": 2}
    d["system"] = {"A": np.eye(3).tolist(), "B": np.eye(3).tolist(), "U": {"kind": "box", "bound": 1}}
    d["zshape"] = {"kind": "diamond"}
    assert str(refused(d)).startswith("zshape.kind: expected box or cell for a 3-D state")


@pytest.mark.parametrize("workspace, field, words", [
    ({"kind": "boxgrid", "lower": [0, 0], "upper": [1], "divisions": 2}, "workspace.upper", "expected 2 numbers"),
    ({"kind": "boxgrid", "lower": [0, 0], "upper": [1, 0], "divisions": 2}, "workspace.upper", "upper > lower"),
    ({"kind": "boxgrid", "lower": [0, 0], "upper": [1, 1], "divisions": [2, 2.5]}, "workspace.divisions",
     "an integer"),
    ({"kind": "boxgrid", "lower": [0, 0], "upper": [1, 1], "divisions": 2, "obstacles": [[[0, 0], [1]]]},
     "workspace.obstacles[0]", "two corners of 2 numbers"),
    ({"kind": "polygon", "file": 7}, "workspace.file", "expected a file path (a string), got 7"),
    ({"kind": "grid"}, "workspace.map_file", "missing"),
])
def test_workspace_fields(workspace, field, words):
    err = refused({**base(), "workspace": workspace})
    assert err.problems[0][0] == field and words in err.problems[0][1]


def test_record_is_json_safe_versioned_and_rebuilds_the_model(tmp_path):
    m = ProblemInputs.from_dict(base())
    rec = m.record()
    text = json.dumps(rec, allow_nan=False)                   # JSON-safe: no NaN or Infinity
    assert rec["version"] == 1
    f = rec["workspace"]["map_file"]
    assert f["path"] == str(TINY) and f["resolved"] == str(TINY.resolve())
    import hashlib
    assert f["sha256"] == hashlib.sha256(TINY.read_bytes()).hexdigest()
    assert rec["disturbance"] == {"kind": "ball", "radius": 0.2}   # numbers as given
    back = from_record(json.loads(text))
    assert back == m and back.record() == rec


def test_record_from_a_relative_path_and_search_dirs():
    d = base()
    d["workspace"]["map_file"] = "tests/data/tiny.txt"
    m = ProblemInputs.from_dict(d, search_dirs=[ROOT])
    rec = m.record()
    assert rec["workspace"]["map_file"]["path"] == "tests/data/tiny.txt"
    assert from_record(rec) == m                               # found again by the resolved path


def test_from_record_refuses_changed_or_missing_files_and_other_versions(tmp_path):
    m = tmp_path / "map.txt"
    m.write_text("1.\n.2\n")
    d = base()
    d["workspace"]["map_file"] = str(m)
    rec = ProblemInputs.from_dict(d).record()
    m.write_text("1#\n.2\n")
    with pytest.raises(InputModelError, match=r"workspace.map_file: the file .*map.txt' changed since it was "
                                              r"recorded \(sha256 [0-9a-f]{12}\.\.\., recorded [0-9a-f]{12}"):
        from_record(rec)
    m.unlink()
    with pytest.raises(InputModelError, match=r"workspace.map_file: file '.*map.txt' not found"):
        from_record(rec)
    for version in (99, None, True, "1"):
        with pytest.raises(InputModelError, match=rf"version: expected 1 .*got {version!r}"):
            from_record({**rec, "version": version})
    with pytest.raises(InputModelError, match="record: expected a mapping"):
        from_record([rec])


def test_build_refuses_a_file_changed_after_validation(tmp_path):
    m = tmp_path / "map.txt"
    m.write_text("1.\n.2\n")
    d = base()
    d["workspace"]["map_file"] = str(m)
    model = ProblemInputs.from_dict(d)
    m.write_text("1.\n#2\n")
    with pytest.raises(InputError, match="changed while it was being used"):
        model.build_decomposition()


def test_several_problems_are_all_listed():
    d = with_value("abstraction.L_max", 0)
    d["zshape"]["scale"] = -1
    err = refused(d)
    fields = [f for f, _ in err.problems]
    assert {"abstraction.L_max", "zshape.scale"} <= set(fields) and "(and 1 more)" in str(err)


def test_sections_validate_alone():
    s = validate_section(SpecSettings, {"sequence": ["A", 3]}, "spec")
    assert s.labels == ["A", "3"] and s.planner == "exact" and s.start_cell is None
    with pytest.raises(InputModelError, match=r"^spec.sequence: expected a list of 1 to 1000 region labels"):
        validate_section(SpecSettings, {"sequence": "13"}, "spec")


def test_models_are_immutable():
    m = ProblemInputs.from_dict(base())
    with pytest.raises(Exception):
        m.zshape.scale = 5.0
    assert copy.deepcopy(m) == m
