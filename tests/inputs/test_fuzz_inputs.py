"""Fuzz targets (issue 11, "what must exist" 7): the grid-map parser, the polygon-workspace YAML parser
and the input model, fed random strings, bytes and dicts. Nothing but the project's own error type
(:class:`tubejax.errors.InputError`) may escape.

Seeded and bounded for CI (``derandomize=True``, 120 examples per target); a bigger run, with
fresh random inputs (``TUBEJAX_FUZZ_RANDOM=1``, then ``--hypothesis-seed=N`` repeats one)::

    TUBEJAX_FUZZ_EXAMPLES=3000 TUBEJAX_FUZZ_RANDOM=1 python -m pytest -q tests/inputs/test_fuzz_inputs.py
"""

import copy
import os
from pathlib import Path

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tubejax.errors import InputError
from tubejax.inputs import ProblemInputs, from_record
from tubejax.model.workspace import load_grid_map, parse_grid_map
from tubejax.model.workspace.polygon import parse_polygon_workspace, parse_polygon_workspace_text

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = int(os.environ.get("TUBEJAX_FUZZ_EXAMPLES", "120"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=os.environ.get("TUBEJAX_FUZZ_RANDOM") != "1",
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])


def accepts_or_refuses(call):
    """Run ``call``; an :class:`InputError` is a clear refusal, anything else escapes and fails the test."""
    try:
        return call()
    except InputError as exc:
        assert str(exc)                              # never an empty message
        return None


# --------------------------------------------------------------------- grid maps
MAP_CHARS = st.sampled_from(list(".#.#..12ab\n\n\r \t%é\x00"))


@FUZZ
@given(st.one_of(st.text(MAP_CHARS, max_size=60), st.text(max_size=40)))
def test_grid_map_text(text):
    d = accepts_or_refuses(lambda: parse_grid_map(text, name="fuzz.txt"))
    if d is not None:                                # accepted: one cell per free character
        assert d.n_cells == sum(ch == "." or (ch.isascii() and ch.isalnum()) for ch in text)


@FUZZ
@given(st.binary(max_size=60))
def test_grid_map_bytes(tmp_path_factory, data):
    p = tmp_path_factory.mktemp("maps") / "fuzz.txt"
    p.write_bytes(data)
    accepts_or_refuses(lambda: load_grid_map(p))


# --------------------------------------------------------------------- polygon workspaces
coord = st.one_of(st.integers(-6, 6), st.floats(-6, 6), st.sampled_from([float("nan"), float("inf"), 10 ** 400,
                                                                            True, "1", None]))
point = st.one_of(st.lists(coord, min_size=2, max_size=2), st.lists(coord, max_size=3), coord)
rectangle = st.tuples(st.integers(0, 5), st.integers(0, 5), st.integers(1, 3), st.integers(1, 3)).map(
    lambda r: [[r[0], r[1]], [r[0] + r[2], r[1]], [r[0] + r[2], r[1] + r[3]], [r[0], r[1] + r[3]]])
small_polygon = st.lists(st.tuples(st.integers(0, 6), st.integers(0, 6)).map(list), min_size=3, max_size=6)
polygon = st.one_of(rectangle, rectangle, small_polygon, st.lists(point, min_size=3, max_size=6), coord)
label = st.one_of(st.integers(0, 3), st.sampled_from(["A", "B", "", True, 1.5, None]))
polygon_doc = st.fixed_dictionaries(
    {"boundary": st.tuples(polygon, st.integers(0, 5)).map(
        lambda t: t[0] if t[1] == 3 else [[[0, 0], [6, 0], [6, 6], [0, 6]],
                                          [[0, 0], [8, 0], [8, 3], [5, 3], [5, 6], [0, 6]]][t[1] % 2])},
    optional={"obstacles": st.one_of(st.lists(polygon, max_size=3), coord),
              "regions": st.one_of(st.dictionaries(label, polygon, max_size=3), coord),
              "max_area": st.one_of(st.floats(0.5, 20), st.floats(0.5, 20), coord),
              "name": st.one_of(st.text(max_size=5), coord)})
polygon_doc = st.tuples(polygon_doc, st.integers(0, 9)).map(lambda t: {**t[0], "extra": 1} if t[1] == 7 else t[0])
json_like = st.recursive(st.one_of(st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=8)),
                         lambda c: st.one_of(st.lists(c, max_size=4), st.dictionaries(st.text(max_size=6), c,
                                                                                      max_size=4)), max_leaves=20)


@FUZZ
@given(st.one_of(polygon_doc, json_like))
def test_polygon_workspace_dict(data):
    accepts_or_refuses(lambda: parse_polygon_workspace(data, name="fuzz.yaml"))


@FUZZ
@given(st.one_of(polygon_doc.map(lambda d: yaml.safe_dump(d, allow_unicode=True)),
                 st.text(st.sampled_from(list("abx:[]{},-&*!|>'\"#%@` \n\t01.<")), max_size=60),
                 st.text(max_size=40)))
def test_polygon_workspace_yaml_text(text):
    accepts_or_refuses(lambda: parse_polygon_workspace_text(text, name="fuzz.yaml"))


# --------------------------------------------------------------------- the input model
BASE = {
    "workspace": {"kind": "grid", "map_file": str(ROOT / "tests" / "data" / "tiny.txt")},
    "system": {"A": [[1.0, 0.0], [0.0, 1.0]], "B": [[0.5, 0.0], [0.0, 0.5]], "U": {"kind": "box", "bound": 1.0}},
    "disturbance": {"kind": "ball", "radius": 0.2},
    "zshape": {"kind": "box", "scale": 1.0},
    "abstraction": {"L_max": 4, "solver": {"name": "highs"}},
    "simulation": {"runs": 5},
    "spec": {"sequence": [1, 2]},
}
odd_value = st.one_of(json_like, st.sampled_from([float("nan"), float("inf"), -float("inf"), 1e9, 1e-9, 10 ** 400,
                                                  True, "abc", [0.1, 0.2], [[1.0]], [[1, 0], [0]], {"kind": "box"},
                                                  {"kind": "polytope", "vertices": [[0, 0], [1, 1], [2, 2]]},
                                                  {"kind": "polytope", "vertices": [[1, 0], [0, 1], [-1, -1]]}]))
matrix2 = st.lists(st.lists(st.floats(-2, 2), min_size=2, max_size=2), min_size=2, max_size=2)
MAPS = ROOT / "conf" / "workspace" / "maps"
#: Per field: values that are often valid (so the model gets built and recorded), besides the odd ones.
LEAVES = {
    ("workspace",): st.sampled_from([
        {"kind": "grid", "map_file": str(MAPS / "open.txt")},
        {"kind": "polygon", "file": str(MAPS / "rooms.yaml")},
        {"kind": "boxgrid", "lower": [0, 0], "upper": [2, 1], "divisions": [4, 2], "obstacles": [[[0, 0], [1, 1]]]},
        {"kind": "boxgrid", "lower": [0, 0], "upper": [1, 1], "divisions": 2, "labels": {"A": [[0, 0], [9, 9]]}}]),
    ("workspace", "map_file"): st.sampled_from(["tests/data/tiny.txt", str(ROOT), "/nonexistent", ""]),
    ("system", "A"): matrix2,
    ("system", "B"): matrix2,
    ("system", "U"): st.sampled_from([{"kind": "one_norm", "radius": 1}, {"kind": "box", "bound": [1, 2]},
                                      {"kind": "polytope", "vertices": [[1, 0], [0, 1], [-1, -1]]}]),
    ("system", "U", "bound"): st.floats(0.01, 3),
    ("disturbance",): st.sampled_from([{"kind": "box", "half_width": 0.1}, {"kind": "ball", "radius": 0},
                                       {"kind": "polytope", "vertices": [[0.1, 0], [0, 0.1], [-0.1, -0.1]]}]),
    ("disturbance", "radius"): st.floats(0, 0.7),
    ("zshape",): st.fixed_dictionaries({"kind": st.sampled_from(["box", "cell", "diamond", "regular"]),
                                        "scale": st.floats(1e-3, 1e3)}),
    ("abstraction",): st.fixed_dictionaries({"L_max": st.integers(1, 9), "pruning": st.booleans(),
                                             "method": st.sampled_from(["tube", "openloop", "exact2d"])}),
    ("abstraction", "solver"): st.sampled_from([{"name": "pdhg"}, {"name": "pdhg", "pool": 32, "min_bucket": 64}]),
    ("simulation", "runs"): st.integers(-2, 10 ** 8),
    ("spec", "sequence"): st.lists(st.sampled_from([1, 2, "A", "x" * 70]), min_size=1, max_size=3),
    ("spec", "start_cell"): st.one_of(st.none(), st.integers(-1, 9)),
}
mutation = st.sampled_from(sorted(LEAVES)).flatmap(
    lambda leaf: st.tuples(st.just(leaf), st.one_of(LEAVES[leaf], LEAVES[leaf], odd_value)))


def check_model(data):
    m = ProblemInputs.from_dict(data, search_dirs=[ROOT])
    m.build_system()
    m.build_decomposition()
    assert from_record(m.record()) == m


@FUZZ
@given(st.lists(mutation, min_size=1, max_size=2))
def test_input_model_mutated_configs(changes):
    data = copy.deepcopy(BASE)
    for leaf, value in changes:
        cur = data
        for k in leaf[:-1]:
            cur[k] = cur[k] if isinstance(cur.get(k), dict) else {}
            cur = cur[k]
        cur[leaf[-1]] = value
    accepts_or_refuses(lambda: check_model(data))


@FUZZ
@given(json_like)
def test_input_model_random_documents(data):
    accepts_or_refuses(lambda: ProblemInputs.from_dict(data))
    accepts_or_refuses(lambda: from_record(data))
