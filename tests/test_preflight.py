"""Issue 48, item 3: an estimate before every run (cells, candidate pairs, LPs, memory), and runs
beyond the budget refused up front with the estimate and the keys that change it: a 1000 x 1000
map, a 1-row map of 10^6 cells, ``workspace.divisions=[1000,1000]``, ``L_max=1000`` on a tiny map."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.abstraction.preflight import (RunBudget, _lp_size, budget_refusal, count_cells, estimate_run)
from tubejax.abstraction.schedule import MemoryBudget
from tubejax.inputs import ProblemInputs
from tubejax.lp.evidence.verdict import highs_solve_batch

ROOT = Path(__file__).resolve().parents[1]
MAPS = ROOT / "conf" / "workspace" / "maps"
SYSTEM = {"A": [[1.0, 0.0], [0.0, 1.0]], "B": [[0.5, 0.0], [0.0, 0.5]], "U": {"kind": "box", "bound": 1.0}}


def _inputs(workspace, L_max=3, system=SYSTEM):
    return ProblemInputs.from_dict({"workspace": workspace, "system": system,
                                    "disturbance": {"kind": "ball", "radius": 0.1},
                                    "abstraction": {"L_max": L_max, "solver": {"name": "highs"}}})


def test_cells_are_counted_before_they_are_built(tmp_path):
    for name, n in (("tiny.txt", 8), ("paper.txt", 67), ("building3d.txt", None)):
        inp = _inputs({"kind": "grid", "map_file": str(MAPS / name)},
                      system={"A": np.eye(3).tolist(), "B": np.eye(3).tolist(), "U": {"kind": "box", "bound": 1.0}}
                      if name == "building3d.txt" else SYSTEM)
        assert count_cells(inp.workspace) == inp.build_decomposition().n_cells == (n or count_cells(inp.workspace))
    box = _inputs({"kind": "boxgrid", "lower": [0.0, 0.0], "upper": [1.0, 1.0], "divisions": [1000, 1000]})
    assert count_cells(box.workspace) == 10 ** 6                    # not built: a million polytopes
    row = tmp_path / "row.txt"
    row.write_text("1" + "." * (10 ** 6 - 2) + "2\n")
    assert count_cells(_inputs({"kind": "grid", "map_file": str(row)}).workspace) == 10 ** 6


@pytest.mark.parametrize("cells", [10 ** 6, 1000 * 1000])
def test_a_million_cells_are_refused_naming_the_keys(cells):
    why = budget_refusal(None, RunBudget(), cells)
    assert why.startswith("budget.max_cells: the workspace has 1,000,000 cells, more than the budget of 250,000")
    assert "workspace.map_file, workspace.divisions" in why and "raise budget.max_cells" in why
    assert budget_refusal(None, RunBudget(max_cells=None), cells) is None
    assert budget_refusal(None, RunBudget(), 250_000) is None


def test_the_estimate_bounds_what_the_run_solves():
    inp = _inputs({"kind": "grid", "map_file": str(MAPS / "paper.txt")}, L_max=4)
    d, s = inp.build_decomposition(), inp.build_system()
    Z = inp.build_cross_sections(d)
    est = estimate_run(d, s, Z, 4, memory_budget_mb=2048)
    ts = build_abstraction(d, s, **inp.abstraction_kwargs(), solve_batch=highs_solve_batch, progress=False, z=Z)
    assert est.n_cells == 67 and 0 < est.n_candidate_pairs <= ts.stats["n_candidate_pairs"]
    assert ts.stats["n_lps"] <= est.n_lps and ts.n_edges <= est.n_candidate_pairs
    assert 0 < est.megabytes < 2048 and "67 cells" in est.line()
    assert budget_refusal(est, RunBudget()) is None


def test_L_max_1000_on_the_tiny_map_is_refused_with_the_reason():
    inp = _inputs({"kind": "grid", "map_file": str(MAPS / "tiny.txt")}, L_max=1000)
    d, s = inp.build_decomposition(), inp.build_system()
    Z = inp.build_cross_sections(d)
    est = estimate_run(d, s, Z, 1000, max_lp_size=25_000)
    # by hand (schedule.lp_dimensions): n = m = 2, square cells and box Z of 4 vertices and 4 facets,
    # S with 8 rows; horizon 1000 padded to 1500: 1500*3 + 1500*4*2 + 1 variables, 1499*8 + 4 + 1500*4*4 rows
    assert est.lp_size == 16_501 + 35_996
    mb = MemoryBudget(None, d, s, Z)
    assert _lp_size(mb, est.largest_fitting_L) <= 25_000 < _lp_size(mb, est.largest_fitting_L + 1)
    why = budget_refusal(est, RunBudget())
    assert why.startswith("L_max: one LP at horizon L_max = 1000 has 52,497 variables and rows, more than "
                          "budget.max_lp_size = 25,000")
    assert f"L_max <= {est.largest_fitting_L} fits" in why and "[estimate: 8 cells," in why
    assert budget_refusal(est, RunBudget(max_lps=100)).startswith("L_max:")          # the size is said first
    small = estimate_run(d, s, Z, 3)
    assert budget_refusal(small, RunBudget(max_lps=10)).startswith(
        f"budget.max_lps: the run would solve up to {small.n_lps:,} LPs, more than the budget of 10")


def test_the_app_refuses_before_building_and_logs_the_estimate(tmp_path):
    def run(*args):
        return subprocess.run([sys.executable, str(ROOT / "experiments" / "abstract.py"), *args, "solver=highs",
                               "progress=false", f"hydra.run.dir={tmp_path / str(len(args))}"], cwd=ROOT,
                              capture_output=True, text=True, timeout=300)

    p = run("workspace=tiny", "L_max=1000")
    assert p.returncode == 2 and p.stderr.strip().splitlines()[-1].startswith("error: L_max: one LP at horizon"), \
        p.stderr[-2000:]
    ok = run("workspace=tiny", "L_max=2", "budget.max_lp_size=null")
    assert ok.returncode == 0 and "estimate: 8 cells" in ok.stdout + ok.stderr, ok.stderr[-2000:]
