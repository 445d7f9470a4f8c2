"""experiments/conservatism.py run as a user would: conservatism.json in the issue's schema, the
figure, each method's run in <method>/ (or read from abstraction_dirs), and bad input refused;
and the Python API (tj.limit, tj.winning_set)."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

import tubejax as tj

ROOT = Path(__file__).resolve().parents[2]
AVOID_MAP = "1.4.2\n.###.\n3....\n"


def run(*overrides, timeout=600):
    return subprocess.run([sys.executable, str(ROOT / "experiments" / "conservatism.py"), "progress=false",
                           *overrides], cwd=ROOT, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def app_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("conservatism")
    (d / "avoid.txt").write_text(AVOID_MAP)
    out = d / "run"
    p = run(f"workspace.map_file={d / 'avoid.txt'}", "target=2", "avoid=[4]", "solver=highs", "L_max=4",
            "disturbance.radius=0.3", "zshape=diamond", f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr[-3000:]
    return d, out, p.stdout


def test_the_json_has_the_issue_schema(app_run):
    _, out, stdout = app_run
    doc = json.loads((out / "conservatism.json").read_text())
    assert set(doc) == {"limit", "free_area", "target_area", "methods", "provenance"}
    assert set(doc["limit"]) == {"area", "iterations", "converged"} and doc["limit"]["converged"] is True
    assert doc["free_area"] == 11.0 and doc["target_area"] == 1.0        # 12 free cells, the avoided one left out
    assert set(doc["methods"]) == {"tube", "exact2d", "openloop"}
    for method, m in doc["methods"].items():
        assert set(m) == {"winning_area", "winning_cells", "fraction_of_limit"}
        n = 12                                                      # cells of the map
        assert all(0 <= c < n for c in m["winning_cells"]) and 2 not in m["winning_cells"]      # cell 2: label 4
        assert m["fraction_of_limit"] == pytest.approx(m["winning_area"] / doc["limit"]["area"])
        assert (out / method / "transitions.json").is_file()
    assert doc["methods"]["tube"]["winning_cells"] == [4]           # the diamond Z finds no edge at r = 0.3
    assert set(doc["methods"]["openloop"]["winning_cells"]) <= set(doc["methods"]["exact2d"]["winning_cells"])
    assert (out / "fig_conservatism.png").is_file() and (out / "fig_conservatism.pdf").is_file()
    assert "converged" in stdout and "fraction of the limit" in stdout


def test_a_run_is_read_from_abstraction_dirs(app_run):
    d, out, _ = app_run
    again = d / "again"
    p = run(f"workspace.map_file={d / 'avoid.txt'}", "target=2", "avoid=[4]", "disturbance.radius=0.3",
            "methods=[exact2d]", f"abstraction_dirs={{exact2d: {out / 'exact2d'}}}", "figures=false",
            f"hydra.run.dir={again}")
    assert p.returncode == 0, p.stderr[-3000:]
    doc = json.loads((again / "conservatism.json").read_text())
    first = json.loads((out / "conservatism.json").read_text())
    assert doc["methods"]["exact2d"] == first["methods"]["exact2d"] and doc["limit"] == first["limit"]
    assert not (again / "exact2d").exists() and not (again / "fig_conservatism.png").exists()
    p = run(f"workspace.map_file={d / 'avoid.txt'}", "target=2", "disturbance.radius=0.2",
            "methods=[exact2d]", f"abstraction_dirs={{exact2d: {out / 'exact2d'}}}", f"hydra.run.dir={d / 'bad'}")
    assert p.returncode == 2 and "is not a run of this problem: its system differs in W" in p.stderr


@pytest.mark.parametrize("override,message", [
    ("target=9", "target: no cell carries the label '9'"),
    ("methods=[tube,tube]", "methods: expected a list of 1 to 3 distinct methods"),
    ("system.A=[[1,1],[1,1]]", "system.A: the limit needs an invertible A"),
])
def test_bad_input_is_one_line(override, message, tmp_path):
    p = run("system=custom" if override.startswith("system.A") else "L_max=2", override,
            f"hydra.run.dir={tmp_path / 'x'}", timeout=120)
    assert p.returncode == 2, p.stderr[-2000:]
    assert message in p.stderr and "Traceback" not in p.stderr


def test_the_python_api():
    ws = tj.grid_map(AVOID_MAP)
    s = tj.paper_system(radius=0.2)
    lim = tj.limit(ws, s, target="2", avoid=["4"])
    assert lim.converged and lim.area == pytest.approx(11.0, abs=1e-6)
    ts = tj.abstract(ws, s, method="exact2d", L_max=4)
    win = tj.winning_set(ts, target="2", avoid=["4"])
    assert 2 not in win.cells and win.area <= lim.area + 1e-9
    with pytest.raises(tj.InputError, match="avoid: no cell carries the label '7'"):
        tj.limit(ws, s, target="2", avoid=["7"])
    with pytest.raises(tj.InputError, match="ts: expected a TransitionSystem"):
        tj.winning_set("x", target="2")
