"""Issue 21, hostile-input findings on configuration: unknown keys (with the key meant), and a box
``W`` or ``U`` too small for its vertices, refused as the polytope with the same vertices is."""

import copy
import sys
from pathlib import Path

import numpy as np
import pytest

from tubejax.errors import InputError, InputModelError
from tubejax.model.geometry import Polytope
from tubejax.inputs import ProblemInputs

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "experiments"))
import common  # noqa: E402
import overrides  # noqa: E402


def check_overrides(args, app):
    overrides.check_overrides(args, app, common.check_keys, common._APP_SCRIPTS)

BASE = {
    "workspace": {"kind": "grid", "map_file": str(ROOT / "tests" / "data" / "tiny.txt")},
    "system": {"name": "integrator2d", "A": [[1.0, 0.0], [0.0, 1.0]], "B": [[0.5, 0.0], [0.0, 0.5]],
               "U": {"kind": "box", "bound": 1.0}},
    "disturbance": {"kind": "ball", "radius": 0.2},
}


def problems(**changes):
    d = copy.deepcopy(BASE)
    d.update(changes)
    with pytest.raises(InputModelError) as e:
        ProblemInputs.from_dict(d)
    return e.value.problems


# ------------------------------------------------------------------ unknown keys
@pytest.mark.parametrize("app, key, expected", [
    ("config", "L_mx", "L_mx: unknown key; did you mean L_max? (experiments/abstract.py has no key 'L_mx')"),
    ("config", "prgress", "prgress: unknown key; did you mean progress?"),
    ("config", "l_max", "l_max: unknown key; did you mean L_max?"),
    ("config", "figures", "figures: unknown key (the keys of experiments/abstract.py: L_max, budget, disturbance"),
    ("config", "spec", "spec: unknown key"),
    ("radius", "radius", "radius: unknown key; did you mean radii?"),
    ("simulate", "adversarial_runs", "adversarial_runs: unknown key"),
    ("simulate", "gap_tol", "gap_tol: unknown key"),
])
def test_a_key_the_app_does_not_read_is_refused(app, key, expected):
    c = {k: None for k in common.APP_KEYS[app]} | {key: 5, "hydra": {}}
    with pytest.raises(common.ConfigError) as e:
        common.check_keys(c, app)
    assert str(e.value).startswith(expected), str(e.value)


@pytest.mark.parametrize("app", ["config", "radius", "simulate", "paper"])
def test_every_key_of_the_apps_own_config_is_known(app):
    """The composed default config of every app passes (no key of ours is refused)."""
    check_overrides([], app)
    common.check_keys({k: None for k in common.APP_KEYS[app]}, app)


@pytest.mark.parametrize("section, c, expected", [
    ("sim", {"sim": {"runs": 2, "run": 3}}, "sim.run: unknown key; did you mean sim.runs?"),
    ("method", {"method": {"name": "tube", "nme": 1}}, "method.nme: unknown key"),
])
def test_sections_read_key_by_key_refuse_unknown_keys(section, c, expected):
    with pytest.raises(common.ConfigError, match=expected.replace("?", r"\?")):
        common.check_keys(c, "simulate")


@pytest.mark.parametrize("args, expected", [
    (["figures=maybe"], "figures: unknown key (the keys of experiments/abstract.py:"),
    (["+L_mx=5"], "L_mx: unknown key; did you mean L_max?"),
    (["disturbance=boxx"], "disturbance: no option 'boxx'; did you mean disturbance=box? (the options of "
                           "disturbance: ball, box, polytope)"),
    (["disturbance=box", "disturbance.radius=0.1"], "disturbance.radius: unknown key (the keys of "
                                                    "disturbance=box: half_width, kind)"),
    (["zshape.scal=2"], "zshape.scal: unknown key; did you mean zshape.scale?"),
    (["L_max=1,2"], "L_max=1,2: several values given"),
    (["L_max=[1"], "L_max=[1: not a valid override"),
])
def test_overrides_hydra_would_refuse_are_refused_in_one_line(args, expected):
    with pytest.raises(InputError) as e:
        check_overrides(args, "config")
    assert str(e.value).startswith(expected) and "\n" not in str(e.value), str(e.value)


@pytest.mark.parametrize("args", [
    ["L_max=3", "disturbance=box", "disturbance.half_width=0.05", "hydra.run.dir=/tmp/x"],
    ["-m", "zshape=box,cell", "shard.count=2", "shard.index=range(2)"],
    ["+experiment=double_integrator"],
    ["zshape=learned", "zshape.steps=3"],
    ["--cfg", "job", "nonsense=1"],                   # other Hydra commands: left to Hydra
])
def test_good_command_lines_pass(args):
    check_overrides(args, "config")


def test_unknown_field_of_a_model_suggests_the_one_meant():
    d = copy.deepcopy(BASE)
    d["disturbance"]["raduis"] = 0.3
    with pytest.raises(InputModelError) as e:
        ProblemInputs.from_dict(d)
    assert e.value.problems == [("disturbance.raduis", "unknown field (value 0.3); did you mean radius?")]


# ------------------------------------------------------------------ sets too small for their vertices
def test_box_w_too_small_for_its_vertices_is_refused_like_the_same_polytope():
    s = 1e-300
    corners = [[-s, -s], [s, -s], [s, s], [-s, s]]
    (field, msg), = problems(disturbance={"kind": "box", "half_width": s})
    assert field == "disturbance.half_width"
    assert msg.startswith("W must have volume: the half-width 1e-300 is too small for its box to have volume")
    (field, msg), = problems(disturbance={"kind": "polytope", "vertices": corners})
    assert field == "disturbance.vertices" and msg.startswith("W must have volume")


@pytest.mark.parametrize("s", [1e-100, 1e-12, 0.1])
def test_box_w_whose_vertices_have_volume_is_accepted_and_its_vertices_rebuild(s):
    d = copy.deepcopy(BASE)
    d["disturbance"] = {"kind": "box", "half_width": s}
    W = ProblemInputs.from_dict(d).build_disturbance()
    assert np.allclose(Polytope.from_vertices(W.vertices).vertices, W.vertices, rtol=0, atol=0)


@pytest.mark.parametrize("U, field", [
    ({"kind": "box", "bound": 1e-300}, "system.U.bound"),
    ({"kind": "box", "bound": [1.0, 1e-300]}, "system.U.bound"),
    ({"kind": "one_norm", "radius": 1e-300}, "system.U.radius"),
])
def test_u_too_small_for_its_vertices_is_refused(U, field):
    d = copy.deepcopy(BASE["system"])
    d["U"] = U
    (f, msg), = problems(system=d)
    assert f == field and msg.startswith("U must have volume"), (f, msg)


@pytest.mark.parametrize("r", [0.0, 5e-324, 1e-300])
def test_ball_w_of_any_radius_in_range_is_accepted(r):
    """A ball is stored by its radius and rebuilt exactly (verify and simulate accept it)."""
    d = copy.deepcopy(BASE)
    d["disturbance"] = {"kind": "ball", "radius": r}
    m = ProblemInputs.from_dict(d)
    assert ProblemInputs.from_record(m.record()).build_disturbance().radius == r
