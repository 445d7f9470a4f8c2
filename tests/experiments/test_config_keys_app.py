"""Issue 21, hostile-input findings on configuration, through the apps as a user runs them: unknown
or mistyped keys, an unusable compilation cache and a W too small for its vertices exit with code 2
and one ``error:`` line naming the key -- never a traceback, never a run that ignores the key."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / "tests" / "data" / "tiny.txt"


def run(app, *overrides):
    return subprocess.run([sys.executable, str(ROOT / "experiments" / app), "progress=false", *overrides],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)


def assert_refused(p, expected: str):
    assert p.returncode == 2, p.stderr[-2000:]
    assert "Traceback" not in p.stderr, p.stderr[-2000:]
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("error: ")]
    assert len(lines) == 1 and expected in lines[0], p.stderr[-2000:]


@pytest.mark.parametrize("app, overrides, expected", [
    ("abstract.py", ["+L_mx=5"], "error: L_mx: unknown key; did you mean L_max?"),
    ("abstract.py", ["figures=maybe"], "error: figures: unknown key (the keys of experiments/abstract.py: "),
    ("abstract.py", ["disturbance=boxx"], "error: disturbance: no option 'boxx'; did you mean disturbance=box?"),
    ("abstract.py", ["+disturbance.raduis=0.1"], "error: disturbance.raduis: unknown field (value 0.1); did you "
                                                 "mean radius?"),
    ("radius.py", ["+L_mx=5"], "error: L_mx: unknown key; did you mean L_max?"),
    ("radius.py", ["figures=maybe"], "error: figures: expected true or false, or a section with keys enabled, width, height, dpi, got 'maybe'"),
    ("simulate.py", ["+L_mx=5"], "error: L_mx: unknown key; did you mean L_max?"),
    ("simulate.py", ["sim.run=3"], "error: sim.run: unknown key; did you mean sim.runs?"),
    ("simulate.py", ["progress=2"], "error: progress: expected true or false, got 2"),
    ("paper.py", ["+L_mx=5"], "error: L_mx: unknown key; did you mean L_max?"),
])
def test_unknown_and_mistyped_keys_are_refused(tmp_path, app, overrides, expected):
    p = run(app, f"workspace.map_file={TINY}", "solver=highs", "L_max=2", *overrides,
            f"hydra.run.dir={tmp_path / 'run'}")
    assert_refused(p, expected)
    assert not (tmp_path / "run" / "transitions.json").exists()


@pytest.mark.parametrize("app, where", [("abstract.py", "file"), ("abstract.py", "proc"), ("radius.py", "below_file")])
def test_unusable_compilation_cache_is_refused_before_the_run(tmp_path, app, where):
    (tmp_path / "afile").write_text("")
    path = {"file": tmp_path / "afile", "below_file": tmp_path / "afile" / "jax",
            "proc": Path("/proc/tubejax-jax-cache")}[where]
    why = {"file": "(it is a file)", "below_file": f"({tmp_path / 'afile'} is a file)",
           "proc": "(no file can be created there"}[where]
    p = run(app, f"workspace.map_file={TINY}", "solver=pdhg", "L_max=2", f"solver.compilation_cache={path}",
            f"hydra.run.dir={tmp_path / 'run'}")
    assert_refused(p, f"error: solver.compilation_cache: cannot keep JAX's compiled code in '{path}' {why}")
    assert not (tmp_path / "run" / "rounds").exists()


def test_box_w_too_small_for_its_vertices_is_refused_before_the_run(tmp_path):
    p = run("abstract.py", f"workspace.map_file={TINY}", "solver=highs", "L_max=2", "disturbance=box",
            "disturbance.half_width=1e-300", f"hydra.run.dir={tmp_path / 'run'}")
    assert_refused(p, "error: disturbance.half_width: W must have volume: the half-width 1e-300 is too small")
    assert not (tmp_path / "run" / "rounds").exists()


@pytest.mark.parametrize("app, args, expected", [
    ("merge.py", ["sweep", "--outt"], "error: unrecognized arguments: --outt; did you mean --out? (usage: "
                                 "merge.py [-h] [--out OUT] sweep_dir)"),
    ("aggregate.py", [], "error: the following arguments are required: sweep_dir (usage: aggregate.py"),
])
def test_command_line_scripts_refuse_bad_arguments_in_one_line(app, args, expected):
    p = subprocess.run([sys.executable, str(ROOT / "experiments" / app), *args], cwd=ROOT, capture_output=True,
                       text=True, timeout=600)
    assert p.returncode == 2 and p.stderr.strip().startswith(expected), p.stderr
    assert len(p.stderr.strip().splitlines()) == 1, p.stderr
