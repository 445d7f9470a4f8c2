"""``python -m tubejax export-controller`` and ``tj.export_controller``: what they write, and bad input."""

import copy
import json

import numpy as np
import pytest

import tubejax as tj
from tubejax.__main__ import main
from tubejax.api_control import EVIDENCE_FAILS

MAP = "1.2\n.#.\n3..\n"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("run")
    ws = tj.grid_map(MAP)
    ts = tj.abstract(ws, tj.paper_system(radius=0.2), solver="highs", L_max=10)
    ts.save(d)
    return d, ts


def test_cli_sequence_writes_both_languages(run_dir, tmp_path, capsys):
    d, ts = run_dir
    assert main(["export-controller", str(d), "--to", "c,python", "--sequence", "1,2,3", "--out", str(tmp_path)]) == 0
    names = {p.name for p in tmp_path.iterdir()}
    assert {"README.md", "Makefile", "tubejax_controller.c", "tubejax_controller.h", "tubejax_controller.py",
            "tubejax_controller.npz", "tubejax_controller.json"} <= names
    desc = json.loads((tmp_path / "tubejax_controller.json").read_text())
    assert desc["plan"]["cycle_edges"] == [] and desc["plan"]["repeats"] == 0
    plan = tj.plan(ts, [1, 2, 3])
    assert desc["plan"]["prefix_edges"] == [int(k) for k in plan.plan.edges]
    assert desc["model"]["W"] == {"kind": "ball", "radius": 0.2, "norm": "euclidean"}
    assert "exported the controller" in capsys.readouterr().out


def test_cli_patrol_repeats_forever_by_default(run_dir, tmp_path):
    d, _ = run_dir
    assert main(["export-controller", str(d), "--to", "python", "--patrol", "2,3", "--start", "1",
                 "--out", str(tmp_path)]) == 0
    desc = json.loads((tmp_path / "tubejax_controller.json").read_text())
    assert desc["plan"]["repeats"] == -1 and desc["plan"]["cycle_edges"]
    assert main(["export-controller", str(d), "--to", "python", "--patrol", "2,3", "--start", "1", "--cycles", "2",
                 "--out", str(tmp_path)]) == 0
    assert json.loads((tmp_path / "tubejax_controller.json").read_text())["plan"]["repeats"] == 2


def test_cli_ltl_exports_the_lasso(run_dir, tmp_path, capsys):
    d, ts = run_dir
    assert main(["export-controller", str(d), "--to", "python", "--ltl", "GF l2 & GF l3", "--start", "1",
                 "--cycles", "3", "--out", str(tmp_path)]) == 0
    desc = json.loads((tmp_path / "tubejax_controller.json").read_text())["plan"]
    sp = tj.plan(ts, ltl="GF l2 & GF l3", start=1)
    assert desc["prefix_edges"] == sp.lasso["prefix_edges"] and desc["cycle_edges"] == sp.lasso["cycle_edges"]
    assert desc["repeats"] == 3 and desc["spec"] == "GF l2 & GF l3"
    assert "repeated 3 times" in capsys.readouterr().out
    assert main(["export-controller", str(d), "--ltl", "GF l2"]) == 2                    # needs --start
    assert "--start" in capsys.readouterr().err
    assert main(["export-controller", str(d), "--ltl", "GF l9", "--start", "1"]) == 2    # no such label
    assert main(["export-controller", str(d), "--ltl", "FG l2 & FG l3", "--start", "1",
                 "--out", str(tmp_path)]) == 1                                          # no plan


def test_cli_bad_input(run_dir, tmp_path, capsys):
    d, _ = run_dir
    assert main(["export-controller", str(d), "--to", "rust", "--sequence", "1,2"]) == 2
    assert "--to" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:                    # no specification
        main(["export-controller", str(d)])
    assert exc.value.code == 2
    assert main(["export-controller", str(tmp_path), "--sequence", "1,2"]) == 2         # no transitions here
    assert main(["export-controller", str(d), "--patrol", "2,3"]) == 2                   # a patrol needs --start
    assert main(["export-controller", str(d), "--formula", "F l2 & G !l2", "--start", "1",
                 "--out", str(tmp_path)]) == 1                                          # no plan
    assert "no plan" in capsys.readouterr().err
    assert main(["frobnicate"]) == 2


def test_api_checks_its_arguments(run_dir, tmp_path):
    _, ts = run_dir
    plan = tj.plan(ts, [1, 2])
    files = tj.export_controller(ts, plan, tmp_path, languages=("python",))
    assert all(f.is_file() for f in files)
    with pytest.raises(tj.InputError, match="ts"):
        tj.export_controller("ts", plan, tmp_path)
    with pytest.raises(tj.InputError, match="plan"):
        tj.export_controller(ts, [1, 2], tmp_path)
    with pytest.raises(tj.InputError, match="tol"):
        tj.export_controller(ts, plan, tmp_path, tol=-1.0)
    assert np.load(tmp_path / "tubejax_controller.npz")["sequence"].size == len(plan.plan.edges)


def test_api_refuses_a_plan_over_a_tampered_tube(run_dir, tmp_path):
    _, ts = run_dir
    plan = tj.plan(ts, [1, 2])
    k = int(plan.plan.edges[0])
    bad = copy.copy(ts)
    bad.tubes = list(ts.tubes)
    tube = ts.tubes[k]
    bad.tubes[k] = tube._replace(u=np.asarray(tube.u) * 5.0)      # inputs far outside U
    with pytest.raises(tj.InputError, match=EVIDENCE_FAILS):
        tj.export_controller(bad, plan, tmp_path / "bad")
    assert not (tmp_path / "bad").exists()
