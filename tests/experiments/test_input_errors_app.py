"""Issue 11, findings 5 and 7, through the apps as a user runs them: every bad value exits with code 2
and one line on stderr naming the config key, the value and what was expected -- never a traceback."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / "tests" / "data" / "tiny.txt"


def run(app, *overrides, cwd=ROOT):
    return subprocess.run([sys.executable, str(ROOT / "experiments" / app), "progress=false", *overrides],
                          cwd=cwd, capture_output=True, text=True, timeout=600)


def assert_refused(p, expected: str):
    assert p.returncode == 2, p.stderr[-2000:]
    assert "Traceback" not in p.stderr, p.stderr[-2000:]
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("error: ")]
    assert len(lines) == 1 and expected in lines[0], p.stderr[-2000:]


@pytest.mark.parametrize("overrides, expected", [
    (["zshape.scale=1e9"], "error: zshape.scale: expected a finite number in [0.001, 1000] (with eps_min = 0 only the shape of Z"),
    (["zshape.scale=1e-9"], "zshape.scale: expected a finite number in [0.001, 1000]"),
    (["zshape.scale=nan"], "zshape.scale: expected a finite number in [0.001, 1000]"),
    (["eps_min=nan"], "error: eps_min: expected a finite number in [0, 1000], got nan"),
    (["system.U.bound=nan"], "system.U.bound: expected a finite number in (0, 1e6]"),
    (["system.U.bound=inf"], "system.U.bound: expected a finite number in (0, 1e6], or a list of such numbers "
                             "(one per input), got inf"),
    (["L_max=true"], "error: L_max: expected an integer in [1, 1000], got True"),
    (["pruning=maybe"], "error: pruning: expected true or false, got 'maybe'"),
    (["system.A=1.0"], "error: system.A: expected a square matrix (a list of n rows of n numbers)"),
    (["disturbance.radius=[0.1,0.2]"], "disturbance.radius: expected a finite number in [0, 1e6], got [0.1, 0.2]"),
    (["disturbance.radius=big"], "disturbance.radius: expected a finite number in [0, 1e6], got 'big'"),
    (["disturbance=box", "disturbance.half_width=nan"], "error: disturbance.half_width: expected a finite number"),
    (["system=custom", "system.U.vertices=[[0,0],[1,1],[-1,-1]]"],
     "error: system.U.vertices: U must have volume: the 3 points do not span R^2"),
    (["disturbance=polytope", "disturbance.vertices=[[0,0],[1,1],[2,2]]"],
     "error: disturbance.vertices: W must have volume"),
    (["solver.pool=100"], "error: solver.pool: expected a power of two, got 100"),
])
def test_abstract_app_refuses_bad_values(tmp_path, overrides, expected):
    p = run("abstract.py", f"workspace.map_file={TINY}", *overrides, f"hydra.run.dir={tmp_path / 'bad'}")
    assert_refused(p, expected)
    assert not (tmp_path / "bad" / "transitions.json").exists()


def test_non_utf8_map_names_the_file(tmp_path):
    m = tmp_path / "latin1.txt"
    m.write_bytes(b"1.\n.\xe92\n")
    p = run("abstract.py", f"workspace.map_file={m}", f"hydra.run.dir={tmp_path / 'x'}")
    assert_refused(p, f"{m}, line 2, column 2: not valid UTF-8 text (byte 0xe9)")


def test_duplicate_key_in_a_config_file(tmp_path):
    (tmp_path / "conf" / "workspace").mkdir(parents=True)
    (tmp_path / "conf" / "workspace" / "dup.yaml").write_text(f"kind: grid\nmap_file: {TINY}\nkind: polygon\n")
    p = run("abstract.py", f"--config-dir={tmp_path / 'conf'}", "workspace=dup", f"hydra.run.dir={tmp_path / 'x'}")
    assert_refused(p, "dup.yaml, line 3, column 1: invalid YAML (duplicate key 'kind' (first at line 1))")


def test_w_larger_than_every_cell_warns_why_there_are_no_edges(tmp_path):
    p = run("abstract.py", f"workspace.map_file={TINY}", "solver=highs", "disturbance.radius=0.6", "L_max=3",
            f"hydra.run.dir={tmp_path / 'w'}")
    assert p.returncode == 0, p.stderr[-2000:]
    assert "warning: the disturbance W fits in no cell" in p.stderr and "no transition can exist" in p.stderr
    assert json.loads((tmp_path / "w" / "transitions.json").read_text())["stats"]["n_edges"] == 0


def test_saved_system_records_its_inputs(tmp_path):
    out = tmp_path / "run"
    p = run("abstract.py", f"workspace.map_file={TINY}", "solver=highs", "L_max=3", f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr[-2000:]
    rec = json.loads((out / "transitions.json").read_text())["inputs"]
    from tubejax.inputs import from_record
    model = from_record(rec)
    assert model.record() == rec and rec["abstraction"]["L_max"] == 3
    assert rec["workspace"]["map_file"]["resolved"] == str(TINY.resolve())


@pytest.mark.parametrize("overrides, expected", [
    (["sim.runs=2.5"], "error: sim.runs: expected an integer in [1, 10000000], got 2.5"),
    (["sim.runs=abc"], "error: sim.runs: expected an integer in [1, 10000000], got 'abc'"),
    (["spec.sequence=5"], "error: spec.sequence: expected a list of 1 to 1000 region labels, e.g. [1, 3], got 5"),
    (["sim.disturbance=wild"], "error: sim.disturbance: expected one of uniform, boundary, adversarial, none"),
    (["figures=maybe"], "error: figures: expected true or false, or a section with keys enabled, width, height, "
                        "dpi, edge, runs_drawn, density, style, columns, view, got 'maybe'"),
    (["figures.dpi=5"], "error: figures.dpi: expected an integer in [20, 2400], got 5"),
])
def test_simulate_app_refuses_bad_values_before_any_work(tmp_path, overrides, expected):
    p = run("simulate.py", f"workspace.map_file={TINY}", "solver=highs", *overrides,
            f"hydra.run.dir={tmp_path / 'bad'}")
    assert_refused(p, expected)
    assert not (tmp_path / "bad" / "transitions.json").exists()       # refused before the abstraction


def test_simulate_app_refuses_damaged_abstraction_dirs(tmp_path):
    good = tmp_path / "good"
    p = run("abstract.py", f"workspace.map_file={TINY}", "solver=highs", "L_max=3", f"hydra.run.dir={good}")
    assert p.returncode == 0, p.stderr[-2000:]
    interrupted = tmp_path / "interrupted"
    interrupted.mkdir()
    (interrupted / "rounds").mkdir()
    (interrupted / "rounds" / "manifest.json").write_text("{}")
    truncated = tmp_path / "truncated"
    shutil.copytree(good, truncated)
    text = (truncated / "transitions.json").read_text()
    (truncated / "transitions.json").write_text(text[: len(text) // 2])
    cases = [
        (good / "transitions.json", "abstraction_dir: expected a directory holding transitions.json and "
                                    "transitions.npz, got the file"),
        (interrupted, "holds no transitions.json and no transitions.npz (rounds/ is there: the run "
                      "was interrupted"),
        (truncated, "transitions.json: not valid JSON at line"),
        (tmp_path / "missing", "abstraction_dir: "),
    ]
    for d, expected in cases:
        p = run("simulate.py", f"abstraction_dir={d}", "spec.sequence=[1,2]", "sim.runs=2", "figures=false",
                f"hydra.run.dir={tmp_path / 'sim'}")
        assert_refused(p, expected)
