"""Issue 48, item 4: each misleading message fixed, each silent acceptance warned about.

A mistyped voxel-layer separator names the map's line (not ``system.A``); a device or a pipe as a
map is named as such (not "not found"); a learned-Z file that is no such file names the user's file
(not the app's copy); a too-long formula names the length limit; a missing stem or a run without
its manifest does not claim an interrupted run; an empty state constraint ``X`` (decided exactly,
checked against HiGHS) and a label box cutting cells are warned about.
"""

import json
import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

from tubejax.abstraction.preflight import empty_state_constraint
from tubejax.errors import InputError
from tubejax.inputs import ProblemInputs, SpecSettings, validate_section
from tubejax.model.workspace import box_grid
from tubejax.model.workspace.boxgrid import LabelCoverageWarning
from tubejax.model.workspace.gridmap import GridMapError
from tubejax.model.workspace.voxelmap import load_map
from tubejax.verify.verifier import verify_directory

ROOT = Path(__file__).resolve().parents[1]
BUILDING = ROOT / "conf" / "workspace" / "maps" / "building3d.txt"
TINY = ROOT / "conf" / "workspace" / "maps" / "tiny.txt"
I3 = {"A": np.eye(3).tolist(), "B": (0.5 * np.eye(3)).tolist(), "U": {"kind": "box", "bound": 1.0}}
I2 = {"A": np.eye(2).tolist(), "B": (0.5 * np.eye(2)).tolist(), "U": {"kind": "box", "bound": 1.0}}


def _inputs(map_file, system=I2):
    return ProblemInputs.from_dict({"workspace": {"kind": "grid", "map_file": str(map_file)}, "system": system,
                                    "disturbance": {"kind": "ball", "radius": 0.1}})


@pytest.mark.parametrize("separator", ["----", "--", "\u2014\u2014\u2014", "\u2013\u2013\u2013", " --- -"])
def test_a_mistyped_layer_separator_names_the_maps_line(tmp_path, separator):
    text = BUILDING.read_text().replace("\n---\n", f"\n{separator}\n", 1)
    line = text.split("\n").index(separator) + 1
    m = tmp_path / "building.txt"
    m.write_text(text)
    with pytest.raises(InputError) as info:
        _inputs(m, I3)
    msg = str(info.value)
    assert "workspace.map_file" in msg and f"line {line}" in msg and "'---'" in msg and "system.A" not in msg
    with pytest.raises(GridMapError, match=f"line {line}: .* is not a layer separator"):
        load_map(m)
    _inputs(BUILDING, I3)                                   # the honest map is a 3-D voxel map


def test_a_device_or_a_pipe_as_a_map_is_named_not_not_found(tmp_path):
    for dev, what in (("/dev/null", "a character device"), ("/dev/zero", "a character device")):
        if Path(dev).exists():
            with pytest.raises(InputError) as info:
                _inputs(dev)
            assert f"expected a regular file, got '{dev}', which is {what}" in str(info.value)
            assert "not found" not in str(info.value)
    fifo = tmp_path / "map.fifo"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="which is a named pipe"):
        _inputs(fifo)
    with pytest.raises(InputError, match="not found"):
        _inputs(tmp_path / "nothing.txt")                   # a missing file is still "not found"


def test_a_formula_over_the_length_limit_names_the_limit():
    with pytest.raises(InputError) as info:
        validate_section(SpecSettings, {"sequence": [1, 2], "formula": "F(l1" + " & F(l2)" * 1250 + ")"}, "spec")
    assert "at most 10,000 characters" in str(info.value) and "this one has 10,005" in str(info.value)
    validate_section(SpecSettings, {"sequence": [1, 2], "formula": "F(l1" + " & F(l2)" * 1200 + ")"}, "spec")   # 9,605: accepted


def test_a_missing_stem_and_a_run_without_manifest_claim_no_interrupted_run(tmp_path):
    d = tmp_path / "run"
    d.mkdir()
    (d / "transitions.json").write_text("{}")
    (d / "transitions.npz").write_bytes(b"")
    (d / "rounds").mkdir()
    (d / "rounds" / "manifest.json").write_text(json.dumps({"status": "complete"}))
    rep = verify_directory(d, stem="nope")
    assert not rep.ok and "interrupted" not in rep.findings[0]
    assert "the transition files of stem 'transitions'; --stem names the stem" in rep.findings[0]
    for f in ("transitions.json", "transitions.npz"):
        (d / f).unlink()
    (d / "rounds" / "manifest.json").unlink()               # round files, no manifest
    (d / "rounds" / "00001-L03.npz").write_bytes(b"")
    f = verify_directory(d).findings[0]
    assert "interrupted" not in f and "no manifest" in f
    (d / "rounds" / "manifest.json").write_text(json.dumps({"status": "running"}))
    assert "holds an interrupted run" in verify_directory(d).findings[0]


def test_an_app_run_without_its_manifest_is_not_called_interrupted(tmp_path):
    d = tmp_path / "run"
    (d / "rounds").mkdir(parents=True)
    (d / "rounds" / "00001-L03.npz").write_bytes(b"")
    for resume in ("false", "true"):
        p = subprocess.run([sys.executable, str(ROOT / "experiments" / "abstract.py"), "workspace=tiny", "L_max=2",
                            "solver=highs", "progress=false", f"resume={resume}", f"hydra.run.dir={d}"], cwd=ROOT,
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 2, p.stderr[-2000:]
        err = p.stderr.strip().splitlines()[-1]
        assert "without its manifest" in err and "interrupted run" not in err and "finished run" not in err, err


def test_a_map_given_as_zshape_file_names_the_users_file(tmp_path):
    mine = tmp_path / "my_z.json"
    shutil.copy(TINY, mine)
    p = subprocess.run([sys.executable, str(ROOT / "experiments" / "abstract.py"), "workspace=tiny", "L_max=2",
                        "zshape=learned", f"zshape.file={mine}", "progress=false",
                        f"hydra.run.dir={tmp_path / 'out'}"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    err = p.stderr.strip().splitlines()[-1]
    assert p.returncode == 2 and err.startswith(f"error: zshape.file: {mine}: ") and "learned_z.json" not in err, err


# ------------------------------------------------------------------ an empty state constraint
def _tiny_with_x(H, h):
    inp = _inputs(TINY, {**I2, "X": {"H": H, "h": h}})
    return inp.build_decomposition(), inp.build_system()


def test_an_empty_state_constraint_is_found_exactly():
    assert "system.X" in empty_state_constraint(*_tiny_with_x([[1.0, 0.0], [-1.0, 0.0]], [-1.0, -1.0]))
    assert "no transition can exist" in empty_state_constraint(*_tiny_with_x([[1.0, 1.0]], [-1e-300]))
    assert empty_state_constraint(*_tiny_with_x([[1.0, 1.0]], [0.0])) is None          # only the corner (0, 0)
    assert empty_state_constraint(*_tiny_with_x([[1.0, 0.0]], [3.0 + 1e-12])) is None
    d, _ = _tiny_with_x([[1.0, 0.0]], [1.0])
    assert empty_state_constraint(d, _inputs(TINY).build_system()) is None              # no X at all


def test_the_exact_emptiness_agrees_with_highs_on_random_constraints():
    rng = np.random.default_rng(3)
    d, _ = _tiny_with_x([[1.0, 0.0]], [1.0])
    agree = 0
    for _ in range(40):
        H = rng.integers(-3, 4, size=(3, 2)).astype(float)
        H[~H.any(axis=1), 0] = 1.0
        h = rng.integers(-6, 7, size=3).astype(float)
        _, s = _tiny_with_x(H.tolist(), h.tolist())
        exact = empty_state_constraint(d, s) is not None
        # HiGHS: max t s.t. H x + t <= h, 0 <= x <= 3 (the tiny map's box), t <= 1; empty iff t* < 0
        res = linprog(np.r_[0.0, 0.0, -1.0], A_ub=np.c_[H, np.ones(3)], b_ub=h,
                      bounds=[(0, 3), (0, 3), (None, 1)], method="highs")
        t = -res.fun
        if abs(t) > 1e-7:                                   # HiGHS clear of its tolerance
            assert exact == (t < 0), (H, h, t)
            agree += 1
    assert agree >= 30


def test_the_app_warns_about_an_empty_state_constraint(tmp_path):
    p = subprocess.run([sys.executable, str(ROOT / "experiments" / "abstract.py"), "workspace=tiny", "L_max=2",
                        "solver=highs", "progress=false", "+system.X={H:[[1.0,0.0],[-1.0,0.0]],h:[-1.0,-1.0]}",
                        f"hydra.run.dir={tmp_path / 'out'}"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    assert any(ln.startswith("warning: system.X: the state constraint holds no point of the workspace")
               for ln in p.stderr.splitlines()), p.stderr[-2000:]


# ------------------------------------------------------------------ label boxes cutting cells
def test_a_label_box_cutting_a_cell_is_warned_about():
    with pytest.warns(LabelCoverageWarning, match=r"labels\['1'\]: .* covers 1 free cell only in part "
                                                  r"\(e.g. cell \[1, 0\], 40 % of it\)"):
        d = box_grid([0, 0], [3, 3], [3, 3], labels={"1": ([0, 0], [1.4, 1]), "2": ([2, 2], [3, 3])})
    assert d.labels.count("1") == 1 and d.labels.count("2") == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        box_grid([0, 0], [3, 3], [3, 3], labels={"1": ([0, 0], [1, 1]), "2": ([2, 2], [3, 3])})   # on grid lines
        box_grid([0, 0], [3, 3], [3, 3], labels={"1": ([0, 0], [1 + 1e-12, 1])})                 # a touch only
