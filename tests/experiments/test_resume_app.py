"""Run directories of experiments/abstract.py as a user meets them (issue 10, items 4 and 5): a run
killed (SIGKILL) or interrupted (SIGINT) after its first round files appear resumes with
``resume=true`` to the identical transition system; a rerun into a directory holding a run is
refused unless resumed or overwritten; a resume with other inputs is refused, naming them; three
shards run through a Hydra multirun (joblib launcher) merge into the unsharded system."""

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
PAPER = ROOT / "conf" / "workspace" / "maps" / "paper.txt"
CORRIDOR = ROOT / "conf" / "workspace" / "maps" / "corridor.txt"


def app(script, *args, **kw):
    return [sys.executable, str(ROOT / "experiments" / script), *args]


def run(script, *args):
    return subprocess.run(app(script, *args), cwd=ROOT, capture_output=True, text=True, timeout=600)


def abstract(out, *overrides, map_file=PAPER):
    return run("abstract.py", "progress=false", "solver=highs", f"workspace.map_file={map_file}",
               f"hydra.run.dir={out}", *overrides)


def error_line(p) -> str:
    assert "Traceback" not in p.stderr, p.stderr[-3000:]
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("error: ")]
    assert len(lines) == 1, p.stderr[-3000:]
    return lines[0]


def same_files(a: Path, b: Path, inputs: bool = True):
    """The two directories hold the same transition system: edges (L, margins, provenance, proof levels)
    and every array of the npz (tubes, rational tubes, cross-sections); and the same inputs record."""
    ja, jb = (json.loads((d / "transitions.json").read_text()) for d in (a, b))
    assert ja["edges"] == jb["edges"] and ja["cells"] == jb["cells"] and len(ja["edges"]) > 10
    assert not inputs or ja["inputs"] == jb["inputs"]
    with np.load(a / "transitions.npz") as za, np.load(b / "transitions.npz") as zb:
        assert sorted(za.files) == sorted(zb.files)
        for k in za.files:
            if k.startswith("nonedge_") and k not in ("nonedge_src", "nonedge_dst", "nonedge_L"):
                continue      # which evidence refutes a non-edge may follow the chunks (a class's
                #               representative settles the members that share its chunk)
            assert np.array_equal(za[k], zb[k]), k


def steps(out: Path) -> int:
    try:
        return len(json.loads((out / "rounds" / "manifest.json").read_text())["steps"])
    except (OSError, ValueError):
        return 0


def interrupt_after_first_step(out: Path, sig, *overrides, map_file=PAPER):
    """Start a run, send ``sig`` once its first step is on disk; returns the finished process.

    The run starts with Ctrl-C's default disposition, as from a terminal. A process inherits an
    ignored SIGINT (``nohup``), and a shell starts a background job (``pytest &`` without job
    control) with SIGINT ignored: the run then finished instead of stopping. A handler, unlike
    ``SIG_IGN``, is reset to the default by ``exec`` (no ``preexec_fn``, which would fork this
    multithreaded process)."""
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        proc = subprocess.Popen(app("abstract.py", "progress=false", "solver=highs", f"workspace.map_file={map_file}",
                                    "memory_budget_mb=1", f"hydra.run.dir={out}", *overrides),
                                cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    finally:
        signal.signal(signal.SIGINT, inherited)
    deadline = time.monotonic() + 300
    proc.sent_at = None
    while proc.poll() is None and time.monotonic() < deadline:
        if steps(out) >= 1:
            proc.send_signal(sig)
            proc.sent_at = steps(out)
            break
        time.sleep(0.005)
    proc.stdout_text, proc.stderr_text = proc.communicate(timeout=300)
    proc.diagnosis = (f"signal sent after step {proc.sent_at} of {steps(out)}; this process's SIGINT handler "
                      f"{signal.getsignal(signal.SIGINT)!r}; stdout {proc.stdout_text[-1500:]!r}; "
                      f"stderr {proc.stderr_text[-1500:]!r}")
    return proc


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The paper map, uninterrupted (map copied: one test changes it)."""
    d = tmp_path_factory.mktemp("ref")
    shutil.copy(PAPER, d / "paper.txt")
    p = abstract(d / "run", map_file=d / "paper.txt")
    assert p.returncode == 0, p.stderr[-3000:]
    return d / "run"


def test_sigkill_then_resume_gives_the_identical_system(tmp_path, reference):
    out = tmp_path / "run"
    proc = interrupt_after_first_step(out, signal.SIGKILL)
    assert proc.returncode == -signal.SIGKILL, proc.stderr_text[-3000:]
    assert not (out / "transitions.json").exists()
    n = steps(out)
    assert n >= 1
    p = abstract(out)                                               # a plain rerun is refused ...
    assert p.returncode == 2
    msg = error_line(p)
    assert f"{out} already holds an interrupted run ({n} finished steps in rounds/); continue it with " \
           "resume=true" in msg and "overwrite=true" in msg
    assert steps(out) == n                                          # ... and touches nothing
    p = abstract(out, "resume=true", "memory_budget_mb=4")          # another budget: same result
    assert p.returncode == 0, p.stderr[-3000:]
    assert "resumed        :" in p.stdout
    same_files(out, reference, inputs=False)                        # (the reference's map is a copy)
    p = abstract(out)
    assert p.returncode == 2 and "already holds a finished run" in error_line(p)


def test_sigint_then_resume_gives_the_identical_system(tmp_path, reference):
    out = tmp_path / "run"
    proc = interrupt_after_first_step(out, signal.SIGINT)
    assert proc.returncode == 130, proc.diagnosis
    assert f"interrupted: the finished steps are in {out / 'rounds'}; continue with resume=true" in proc.stderr_text
    assert "Traceback" not in proc.stderr_text and not (out / "transitions.json").exists()
    p = abstract(out, "resume=true")
    assert p.returncode == 0, p.stderr[-3000:]
    same_files(out, reference, inputs=False)


def test_resume_refuses_other_inputs_naming_them(tmp_path, reference):
    map_file = reference.parent / "paper.txt"
    p = abstract(reference, "resume=true", "disturbance.radius=0.1", "L_max=8", map_file=map_file)
    assert p.returncode == 2
    msg = error_line(p)
    assert "resume: the inputs differ from those of the run in" in msg
    assert "L_max: 10 in the run, 8 now" in msg and "disturbance.radius: 0.2 in the run, 0.1 now" in msg
    text = map_file.read_text()
    try:
        map_file.write_text(text.replace(".", "#", 1))
        p = abstract(reference, "resume=true", map_file=map_file)
        assert p.returncode == 2 and "workspace.map_file: the file changed (SHA-256" in error_line(p)
    finally:
        map_file.write_text(text)
    p = abstract(reference, "resume=true", "overwrite=true", map_file=map_file)
    assert p.returncode == 2 and "not both" in error_line(p)
    assert (reference / "transitions.json").exists()


def test_overwrite_deletes_the_previous_run(tmp_path):
    out = tmp_path / "run"
    assert abstract(out, "L_max=4", map_file=CORRIDOR).returncode == 0
    p = abstract(out, "L_max=5", "overwrite=true", map_file=CORRIDOR)
    assert p.returncode == 0, p.stderr[-3000:]
    data = json.loads((out / "transitions.json").read_text())
    assert data["inputs"]["abstraction"]["L_max"] == 5 and data["stats"]["resumed_lps"] == 0


def test_three_shards_through_a_joblib_multirun_merge_into_the_unsharded_system(tmp_path):
    full = tmp_path / "full"
    assert abstract(full, map_file=CORRIDOR).returncode == 0
    sweep = tmp_path / "sweep"
    p = run("abstract.py", "-m", "progress=false", "solver=highs", f"workspace.map_file={CORRIDOR}",
            "hydra/launcher=parallel", "shard.count=3", "shard.index=0,1,2", f"hydra.sweep.dir={sweep}")
    assert p.returncode == 0, p.stderr[-3000:]
    shards = sorted(d for d in sweep.iterdir() if (d / "transitions.json").exists())
    assert len(shards) == 3
    counts = [len(json.loads((d / "transitions.json").read_text())["edges"]) for d in shards]
    assert all(c > 0 for c in counts)
    m = run("merge.py", str(sweep))
    assert m.returncode == 0, m.stderr[-3000:]
    same_files(sweep / "merged", full)
    assert sum(counts) == len(json.loads((full / "transitions.json").read_text())["edges"])
    v = subprocess.run([sys.executable, "-m", "tubejax", "verify", str(sweep / "merged"), "--quiet"],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert v.returncode == 0 and "verify OK" in v.stdout, v.stdout + v.stderr
    # refusals: a missing shard, a shard of other inputs, an unfinished shard
    shutil.move(shards[1], tmp_path / "away")
    m = run("merge.py", str(sweep))
    assert m.returncode == 2 and "missing shard 1 of 3 (found 0, 2)" in error_line(m)
    p = abstract(shards[1], "shard.count=3", "shard.index=1", "L_max=6", map_file=CORRIDOR)
    assert p.returncode == 0, p.stderr[-3000:]
    m = run("merge.py", str(sweep))
    assert m.returncode == 2 and "shards of different inputs: inputs.abstraction.L_max: 10 in" in error_line(m)
    shutil.rmtree(shards[1])
    shutil.move(tmp_path / "away", shards[1])
    man = shards[1] / "rounds" / "manifest.json"
    man.write_text(man.read_text().replace('"status": "complete"', '"status": "running"'))
    m = run("merge.py", str(sweep))
    assert m.returncode == 2
    assert f"{shards[1]}: this shard's run is unfinished; continue it with: python experiments/abstract.py " \
           in error_line(m) and f"resume=true hydra.run.dir={shards[1]}" in error_line(m)


def test_simulate_refuses_a_shard(tmp_path):
    p = run("simulate.py", "progress=false", "solver=highs", f"workspace.map_file={CORRIDOR}", "shard.count=2",
            "figures=false", f"hydra.run.dir={tmp_path / 'sim'}")
    assert p.returncode == 2 and "shard.count: a shard (2 in all) holds only part" in error_line(p)


@pytest.mark.parametrize("overrides, expected", [
    (["shard.count=3", "shard.index=3"], "error: shard.index: expected an integer in [0, 2] (shard.count = 3), got 3"),
    (["shard.count=0"], "error: shard.count: expected an integer in [1, 100000], got 0"),
    (["memory_budget_mb=0"], "error: memory_budget_mb: expected an integer in [1, 10000000], got 0"),
    (["resume=maybe"], "error: resume: expected true or false, got 'maybe'"),
])
def test_new_keys_are_validated(tmp_path, overrides, expected):
    p = abstract(tmp_path / "bad", *overrides, map_file=CORRIDOR)
    assert p.returncode == 2 and expected in error_line(p)
    assert not (tmp_path / "bad" / "rounds").exists()
