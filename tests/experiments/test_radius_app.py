"""experiments/radius.py run as a user would: radius.json, verified r<radius>/ systems that the
verifier and the simulator accept, the batched path, and bad input refused clearly."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def run(app, *overrides, timeout=900):
    return subprocess.run([sys.executable, str(ROOT / "experiments" / app), "progress=false", *overrides],
                          cwd=ROOT, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def highs_run(tmp_path_factory, corridor_path):
    out = tmp_path_factory.mktemp("radius") / "run"
    p = run("radius.py", f"workspace.map_file={corridor_path}", "solver=highs", "radii=[0.05,0.2]",
            f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr[-3000:]
    return out, p.stdout


def test_radius_json(highs_run):
    out, stdout = highs_run
    doc = json.loads((out / "radius.json").read_text())
    assert doc["format"] == "tubejax.radius" and doc["version"] == 1 and doc["L_max"] == 10
    assert doc["disturbance"]["unit"] == "the radius of the ball W" and doc["radii"] == [0.05, 0.2]
    assert set(doc["forms"]) == {"tube", "openloop"}
    tube = doc["forms"]["tube"]
    inst = tube["instances"]
    assert len(inst["from"]) == len(inst["rho_star"]) == len(inst["lower"]) == len(inst["upper"]) == 834
    assert all(lo <= v <= up for lo, v, up in zip(inst["lower"], inst["rho_star"], inst["upper"]))
    assert all(tube["pairs"]["exact"]) and len(tube["pairs"]["from"]) == 102
    step = tube["n_edges"]
    assert step["n_edges"] == sorted(step["n_edges"], reverse=True) and step["n_edges"][0] == 102
    by_L = tube["n_edges_by_L_max"]
    assert by_L["L_max"] == list(range(1, 11)) and by_L["steps"][-1] == step
    vs = tube["n_edges_vs_L_max"]
    assert vs["radii"] == [0.05, 0.2] and vs["n_edges"][1][-1] == 78           # the corridor's 78 at r = 0.2
    sys02 = doc["systems"]["0.2"]
    assert sys02["directory"] == "r0.2" and sys02["n_edges"] == 78 and sys02["n_edges_vs_L_max"] == vs["n_edges"][1]
    assert doc["forms"]["openloop"]["n_edges_vs_L_max"]["n_edges"][0][-1] == 102
    assert "radius 0.2    : 78 edges (tube)" in stdout
    assert (out / "fig_radius.png").stat().st_size > 10_000 and (out / "fig_radius.pdf").is_file()


@pytest.mark.parametrize("r, n", [("0.05", 102), ("0.2", 78)])
def test_systems_at_radii_verify_and_simulate(highs_run, tmp_path, r, n):
    out, _ = highs_run
    d = out / f"r{r}"
    data = json.loads((d / "transitions.json").read_text())
    assert data["inputs"]["disturbance"] == {"kind": "ball", "radius": float(r)}
    assert data["system"]["W"]["radius"] == float(r) and len(data["edges"]) == n
    assert all(e["rho_star"] >= float(r) for e in data["edges"])
    assert json.loads((d / "metrics.json").read_text())["radius"] == float(r)
    v = subprocess.run([sys.executable, "-m", "tubejax", "verify", str(d), "--quiet"], cwd=ROOT,
                       capture_output=True, text=True, timeout=600)
    assert v.returncode == 0 and "verify OK" in v.stdout, v.stdout + v.stderr
    p = run("simulate.py", f"abstraction_dir={d}", "spec.sequence=[1,2]", "sim.runs=100",
            "sim.disturbance=adversarial", "figures=false", f"hydra.run.dir={tmp_path / 'sim'}")
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads((tmp_path / "sim" / "simulation.json").read_text())
    assert s["runs_reaching_all_targets"] == 100 and s["tube_exits"] == 0 and s["obstacle_entries"] == 0


def test_batched_path(tmp_path, corridor_path):
    """The default solver (the batched engine) on a short horizon, open-loop systems."""
    out = tmp_path / "pdhg"
    p = run("radius.py", f"workspace.map_file={corridor_path}", "method=openloop", "radius_methods=[openloop]",
            "L_max=4", "radii=[0.1]", "solver.compilation_cache=null", f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr[-3000:]
    doc = json.loads((out / "radius.json").read_text())
    assert set(doc["forms"]) == {"openloop"}
    st = doc["forms"]["openloop"]["stats"]
    assert st["solver"] == "pdhg" and st["compile_seconds"] > 0
    assert st["status_counts"] == {"optimal": st["n_instances"]}
    edges = json.loads((out / "r0.1" / "transitions.json").read_text())["edges"]
    assert {e["provenance"] for e in edges} <= {"pdhg+highs", "highs-fallback"} and len(edges) == 68
    v = subprocess.run([sys.executable, "-m", "tubejax", "verify", str(out / "r0.1"), "--quiet"], cwd=ROOT,
                       capture_output=True, text=True, timeout=600)
    assert v.returncode == 0, v.stdout + v.stderr


@pytest.mark.parametrize("overrides, match", [
    (["radii=[0.1,-0.2]"], "radii[1]: expected a finite number in [0, 1e6], got -0.2"),
    (["radii=[0.1,0.1]"], "radii: expected distinct values, got 0.1 twice"),
    (["method=exact2d", "radii=[0.1]"], "method: expected tube or openloop for the systems at radii"),
    (["disturbance=box", "radii=[0.0]"], "radii: radius 0.0: a box disturbance of size 0 is not a valid W"),
    (["gap_tol=0.5"], "gap_tol: expected a finite number in [1e-9, 0.01]"),
    (["radius_methods=[tube,exact2d]"], "radius_methods[1]: expected one of tube, openloop, got 'exact2d'"),
    (["shard.count=2"], "shard.count: expected 1 (experiments/radius.py solves every source cell"),
])
def test_bad_input_is_refused_clearly(tmp_path, corridor_path, overrides, match):
    p = run("radius.py", f"workspace.map_file={corridor_path}", *overrides, f"hydra.run.dir={tmp_path / 'bad'}")
    assert p.returncode == 2 and match in p.stderr, p.stderr[-2000:]
    assert "Traceback" not in p.stderr
