"""experiments/simulate.py and the README's main command experiments/paper.py, run as a user would."""

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def run(app, *overrides, timeout=900):
    return subprocess.run([sys.executable, str(ROOT / "experiments" / app), "progress=false", *overrides],
                          cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def test_simulate_app_on_corridor(tmp_path, corridor_path):
    out = tmp_path / "sim"
    p = run("simulate.py", f"workspace.map_file={corridor_path}", "solver=highs", "spec.sequence=[1,2]", "sim.runs=300",
            "sim.disturbance=adversarial", f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads((out / "simulation.json").read_text())
    assert s["runs"] == 300 and s["obstacle_entries"] == 0 and s["tube_exits"] == 0
    assert s["runs_reaching_all_targets"] == 300
    for stem in ("fig5_workspace", "fig6_tube", "fig7_trajectories", "transition_graph"):
        assert (out / f"{stem}.png").stat().st_size > 5000 and (out / f"{stem}.pdf").exists()
    # reuse the abstraction just written (abstraction_dir), now with disturbances on the boundary of W
    p2 = run("simulate.py", f"abstraction_dir={out}", "spec.sequence=[1,2]", "sim.runs=300",
             "sim.disturbance=boundary", "figures=false", f"hydra.run.dir={tmp_path / 'reuse'}")
    assert p2.returncode == 0, p2.stderr[-3000:]
    assert json.loads((tmp_path / "reuse" / "simulation.json").read_text())["tube_exits"] == 0


def test_unreachable_specification_names_the_segment(tmp_path):
    m = tmp_path / "split.txt"
    m.write_text("1.#.2\n")                     # two components: region 2 cannot be reached from 1
    p = run("simulate.py", f"workspace.map_file={m}", "solver=highs", "spec.sequence=[1,2]", "L_max=4",
            f"hydra.run.dir={tmp_path / 'x'}")
    assert p.returncode == 2
    assert "segment 1" in p.stderr and "labelled 2" in p.stderr


def test_paper_example_end_to_end(tmp_path):
    """The README's main command: 10,050 runs, 0 obstacle entries, 0 tube exits, all targets reached."""
    out = tmp_path / "paper"
    p = run("paper.py", f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr[-3000:]
    assert "states         :     67   (paper: 67)" in p.stdout
    assert "(paper: 655; our map differs: docs/getting-started.md#why-the-counts-differ-from-the-paper)" in p.stdout
    assert "plan           : 1 -> 3 -> 4 -> 5 -> 6 through cells" in p.stdout
    assert "Unable to initialize backend" not in p.stdout + p.stderr
    s = json.loads((out / "simulation.json").read_text())
    assert s["runs"] == 10050
    assert s["obstacle_entries"] == 0 and s["tube_exits"] == 0 and s["runs_reaching_all_targets"] == 10050
    assert s["paper_runs"]["runs"] == 50 and s["adversarial_runs"]["runs"] == 10000
    data = json.loads((out / "transitions.json").read_text())
    assert data["stats"]["n_cells"] == 67 and len(data["edges"]) == data["stats"]["n_edges"] > 0
    assert data["stats"]["solver"] == "pdhg"                      # the default path: batched PDHG
    assert data["stats"]["solver_stats"]["highs_disagreements"] == 0
    assert (out / "fig7_trajectories.png").exists() and (out / "metrics.json").exists()


FINDING4_MAP = "1..2\n.#..\n...3\n"


def test_highs_abstraction_simulates_in_float64(tmp_path):
    """Issue 11, finding 4: with solver=highs nothing enabled x64, so the simulation ran in float32
    and reported 50 obstacle entries for a correct abstraction; it always runs in float64 now."""
    m = tmp_path / "small.txt"
    m.write_text(FINDING4_MAP)
    a = run("abstract.py", f"workspace.map_file={m}", "solver=highs", "disturbance.radius=0.1", "L_max=6",
            f"hydra.run.dir={tmp_path / 'abs'}")
    assert a.returncode == 0, a.stderr[-3000:]
    p = run("simulate.py", f"abstraction_dir={tmp_path / 'abs'}", "spec.sequence=[1,2]", "sim.disturbance=adversarial",
            "figures=false", f"hydra.run.dir={tmp_path / 'sim'}")
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads((tmp_path / "sim" / "simulation.json").read_text())
    assert s["runs"] == 50 and s["obstacle_entries"] == 0 and s["tube_exits"] == 0 and s["workspace_exits"] == 0
    assert s["runs_reaching_all_targets"] == 50
    assert "workspace exits 0" in p.stdout


def test_a_violating_simulation_exits_nonzero(tmp_path):
    """A disturbance larger than the design W (the file edited by hand) makes runs leave their
    tubes: the app reports it and exits non-zero instead of 0."""
    m = tmp_path / "small.txt"
    m.write_text(FINDING4_MAP)
    a = run("abstract.py", f"workspace.map_file={m}", "solver=highs", "disturbance.radius=0.1", "L_max=6",
            f"hydra.run.dir={tmp_path / 'abs'}")
    assert a.returncode == 0, a.stderr[-3000:]
    jpath = tmp_path / "abs" / "transitions.json"
    data = json.loads(jpath.read_text())
    data["system"]["W"]["radius"] = 0.45
    jpath.write_text(json.dumps(data))
    p = run("simulate.py", f"abstraction_dir={tmp_path / 'abs'}", "spec.sequence=[1,2]", "sim.disturbance=adversarial",
            "figures=false", f"hydra.run.dir={tmp_path / 'sim'}")
    assert p.returncode != 0
    assert "error:" in p.stderr and "Traceback" not in p.stderr
