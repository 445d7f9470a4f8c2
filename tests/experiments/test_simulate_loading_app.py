"""Issue 21: experiments/simulate.py with abstraction_dir loads as strictly as `python -m tubejax
verify` (status 2, one `error:` line naming the file, field or value), refuses overrides that
contradict the loaded run, runs without tubes and a deleted learned Z; many runs go in chunks."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tubejax.transitions.file_format import sha256_file
from tubejax.analyses.control import SimulationRuns

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "experiments"))


def run(app, *overrides, timeout=600):
    return subprocess.run([sys.executable, str(ROOT / "experiments" / app), "progress=false", *overrides],
                          cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def verify(d):
    return subprocess.run([sys.executable, "-m", "tubejax", "verify", str(d), "--quiet"], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


def simulate(abs_dir, out, *extra):
    return run("simulate.py", f"abstraction_dir={abs_dir}", "spec.sequence=[1,2]", "sim.runs=20", "figures=false",
               f"hydra.run.dir={out}", *extra)


def one_error(p, *expect):
    """Status 2 and one `error:` line holding every string of ``expect``, no traceback."""
    assert p.returncode == 2, p.stdout[-2000:] + p.stderr[-2000:]
    lines = [line for line in p.stderr.splitlines() if line.startswith("error:")]
    assert len(lines) == 1 and "Traceback" not in p.stderr + p.stdout, p.stderr[-2000:]
    for e in expect:
        assert e in lines[0], lines[0]


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """experiments/abstract.py on the tiny map (HiGHS, L_max = 6): transitions.json|npz and metrics.json."""
    d = tmp_path_factory.mktemp("tiny") / "run"
    p = run("abstract.py", "workspace=tiny", "solver=highs", "L_max=6", f"hydra.run.dir={d}")
    assert p.returncode == 0, p.stderr[-3000:]
    return d


def tamper(run_dir: Path, edit_json=None, edit_npz=None):
    """Edit a run's json (a dict) and/or npz (a dict of arrays), keeping the recorded npz hash right."""
    jpath, npath = run_dir / "transitions.json", run_dir / "transitions.npz"
    if edit_npz is not None:
        with np.load(npath) as z:
            arrays = {k: z[k] for k in z.files}
        edit_npz(arrays)
        with open(npath, "wb") as f:
            np.savez_compressed(f, **arrays)
    data = json.loads(jpath.read_text())
    if edit_json is not None:
        edit_json(data)
    data["npz_sha256"] = sha256_file(npath)
    jpath.write_text(json.dumps(data))


def _swap(d):
    e = d["edges"][0]
    e["from"], e["to"] = e["to"], e["from"]


def _cut_npz(d: Path):
    npath = d / "transitions.npz"
    data = npath.read_bytes()
    npath.write_bytes(data[: len(data) // 2])
    tamper(d)


def _metrics_999(d: Path):
    m = json.loads((d / "metrics.json").read_text())
    (d / "metrics.json").write_text(json.dumps(dict(m, n_edges=999)))


@pytest.mark.parametrize("damage, expect", [
    (lambda d: tamper(d, _swap), "a second edge for the same pair"),
    (lambda d: tamper(d, lambda j: j["edges"][0].update(provenance="magic")), "provenance 'magic' is not one"),
    (lambda d: tamper(d, lambda j: j.update(inputs=None)), "no inputs record"),
    (lambda d: tamper(d, lambda j: j["inputs"]["abstraction"]["shard"].update(count=2, index=0)),
     "the file claims shard 0 of 2"),
    (_cut_npz, "cannot read the npz"),
    (_metrics_999, "metrics.json: field 'n_edges' is 999"),
], ids=["swapped", "magic", "no-inputs", "shard", "cut-npz", "metrics"])
def test_simulate_refuses_what_verify_refuses(tiny_run, tmp_path, damage, expect):
    d = tmp_path / "run"
    shutil.copytree(tiny_run, d)
    damage(d)
    one_error(simulate(d, tmp_path / "sim"), "abstraction_dir: cannot load the transition system", expect)
    assert not (tmp_path / "sim" / "simulation.json").exists()


def test_overrides_that_contradict_the_run_are_refused(tiny_run, tmp_path):
    one_error(simulate(tiny_run, tmp_path / "a", "disturbance.radius=0.5"),
              "disturbance.radius=0.5: contradicts the loaded run", "disturbance.radius: 0.2 in the run, 0.5 given")
    one_error(simulate(tiny_run, tmp_path / "b", "workspace=corridor"), "workspace=corridor: contradicts")
    # overrides equal to the run's values are fine, and change nothing
    plain = simulate(tiny_run, tmp_path / "c")
    same = simulate(tiny_run, tmp_path / "d", "disturbance.radius=0.2", "workspace=tiny", "solver=highs", "L_max=6")
    assert plain.returncode == 0 and same.returncode == 0, plain.stderr[-2000:] + same.stderr[-2000:]
    c, d = (json.loads((tmp_path / x / "simulation.json").read_text()) for x in ("c", "d"))
    assert c.pop("provenance")["command"] != d.pop("provenance")["command"]      # only the command line differs
    assert c == d


def test_a_system_without_tubes_is_refused_clearly(tmp_path):
    d = tmp_path / "exact2d"
    p = run("abstract.py", "workspace=tiny", "method=exact2d", "L_max=6", f"hydra.run.dir={d}")
    assert p.returncode == 0, p.stderr[-3000:]
    one_error(simulate(d, tmp_path / "sim"), "method 'exact2d': the system stores no evidence")
    one_error(run("simulate.py", "workspace=tiny", "method=exact2d", "L_max=6", "spec.sequence=[1,2]",
                  f"hydra.run.dir={tmp_path / 'built'}"), "method: 'exact2d' stores no tubes")
    assert not (tmp_path / "built" / "transitions.json").exists()          # refused before any work


def test_a_deleted_learned_z_is_refused_by_verify_and_simulate(tmp_path):
    d = tmp_path / "learned"
    p = run("abstract.py", "workspace=tiny", "solver=highs", "L_max=6", "zshape=learned", "zshape.steps=1",
            f"hydra.run.dir={d}")
    assert p.returncode == 0, p.stderr[-3000:]
    assert verify(d).returncode == 0
    copy = tmp_path / "copy"                   # a copy of the run without its learned Z (the original remains)
    shutil.copytree(d, copy)
    (copy / "learned_z.json").unlink()
    v = verify(copy)
    assert v.returncode == 1 and f"{copy / 'learned_z.json'}: no such file" in v.stdout, v.stdout[-2000:]
    one_error(simulate(copy, tmp_path / "sim"), f"{copy / 'learned_z.json'}: no such file")


def test_many_runs_go_in_chunks_through_the_app(tmp_path, monkeypatch):
    """run_spec_simulation in chunks: the counts of all chunks, each chunk the simulation of its seed."""
    import simulate as app

    from tubejax.abstraction import build_abstraction
    from tubejax.analyses.control import chunks
    from tubejax.model.geometry import Ball
    from tubejax.analyses.spec import plan_patrol, simulate_spec
    from tubejax.model.system import LinearSystem, box_input_set
    from tubejax.model.workspace.gridmap import load_grid_map

    d = load_grid_map(str(ROOT / "conf" / "workspace" / "maps" / "tiny.txt"))
    ts = build_abstraction(d, LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2)),
                           L_max=6, progress=False)
    sp = plan_patrol(ts, d.cells_with_label("1")[0], ["1", "2"], cycles=2)
    whole = app.run_spec_simulation(ts, sp, 30, "adversarial", 5)[1]
    assert whole == simulate_spec(ts, sp, SimulationRuns(n_runs=30, mode="adversarial", seed=5)).summary()
    per_run = (sp.plan.cost + 1) * chunks.run_step_bytes(2, 2, 4)
    monkeypatch.setattr(chunks, "CHUNK_BYTES", 12 * per_run)              # 12 runs per chunk
    res, s = app.run_spec_simulation(ts, sp, 30, "adversarial", 5)
    assert (s["chunks"], s["runs_per_chunk"], s["runs"], s["seed"]) == (3, 12, 30, 5)
    parts = [simulate_spec(ts, sp, SimulationRuns(n_runs=n, mode="adversarial", seed=chunks.chunk_seed(5, c))).summary()
             for c, n in enumerate((12, 12, 6))]
    for key in ("runs_satisfying_spec", "runs_reaching_all_targets", "tube_exits", "avoided_region_entries"):
        assert s[key] == sum(p[key] for p in parts)
    assert s["runs_satisfying_spec"] == 30 and res.trajectories.shape[0] == 12
