"""Transition files before format 3 are refused with the converter's command, and the converter
(scripts/convert_transitions.py) turns them into current files that verify from their sources.

tests/data/format2 is the paper-like map written by the commit before margins became state-space
distances (format 2, margins per unit of the LP coefficients)."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tubejax.errors import InputError
from tubejax.transitions.file_format import FORMAT_VERSION, TransitionFileError
from tubejax.transitions.transition_system import TransitionSystem
from tubejax.verify.verifier import verify_directory

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
try:
    from convert_transitions import convert
finally:
    sys.path.remove(str(ROOT / "scripts"))


@pytest.fixture
def old_run(tmp_path):
    """A copy of tests/data/format2 whose inputs record finds its map in the copy."""
    old = tmp_path / "old"
    shutil.copytree(ROOT / "tests" / "data" / "format2", old)
    run = old / "run"
    data = json.loads((run / "transitions.json").read_text())
    assert data["version"] == 2 and "margin_scaling" not in data
    data["inputs"]["workspace"]["map_file"]["resolved"] = str(old / "map.txt")
    (run / "transitions.json").write_text(json.dumps(data))
    return run


@pytest.mark.parametrize("version", [1, 2])
def test_a_file_before_format_3_is_refused_naming_the_converter(old_run, version):
    data = json.loads((old_run / "transitions.json").read_text())
    data["version"] = version
    (old_run / "transitions.json").write_text(json.dumps(data))
    with pytest.raises(TransitionFileError, match=rf"transitions.json: field 'version' is {version}: files before "
                                                  r"version 3 are no longer read .*scripts/convert_transitions.py"):
        TransitionSystem.load(old_run)


def test_verify_refuses_it_without_a_traceback(old_run):
    p = subprocess.run([sys.executable, "-m", "tubejax", "verify", str(old_run), "--quiet"], cwd=ROOT,
                       capture_output=True, text=True, timeout=300)
    assert p.returncode != 0 and "Traceback" not in p.stdout + p.stderr
    assert "scripts/convert_transitions.py" in p.stdout + p.stderr


def test_the_converted_file_keeps_the_edges_and_verifies(old_run, tmp_path):
    old = json.loads((old_run / "transitions.json").read_text())
    with np.load(old_run / "transitions.npz") as z:
        old_arrays = {k: z[k] for k in z.files}
    new_run = tmp_path / "new" / "run"
    ts = convert(old_run, new_run)
    data = json.loads((new_run / "transitions.json").read_text())
    assert data["version"] == FORMAT_VERSION and data["margin_scaling"] == "state"
    assert data["inputs"] == old["inputs"]
    assert [(e["from"], e["to"], e["L"]) for e in data["edges"]] == [(e["from"], e["to"], e["L"])
                                                                      for e in old["edges"]]
    with np.load(new_run / "transitions.npz") as z:            # the evidence itself is unchanged
        for k, a in old_arrays.items():
            if k != "format_version":
                np.testing.assert_array_equal(z[k], a)
    shift = max(abs(e["margin"] - o["margin"]) for e, o in zip(data["edges"], old["edges"]))
    assert shift > 1e-3                                        # the margins changed units
    assert ts.margin_scaling == "state" and ts.n_edges == len(old["edges"]) > 10
    rep = verify_directory(new_run, complete=True)
    assert rep.ok, rep.findings
    data["edges"][0]["margin"] = old["edges"][0]["margin"]     # an old-unit margin is caught
    (new_run / "transitions.json").write_text(json.dumps(data))
    assert not verify_directory(new_run).ok


def test_the_converter_refuses_a_demanded_margin_and_a_current_file(old_run, tmp_path):
    data = json.loads((old_run / "transitions.json").read_text())
    data["min_margin"] = 0.01
    (old_run / "transitions.json").write_text(json.dumps(data))
    with pytest.raises(InputError, match="min_margin is 0.01 in the old units .* rerun the abstraction"):
        convert(old_run, tmp_path / "a")
    data.update(min_margin=0.0, version=3)
    (old_run / "transitions.json").write_text(json.dumps(data))
    with pytest.raises(InputError, match="this script converts versions 1, 2"):
        convert(old_run, tmp_path / "b")
