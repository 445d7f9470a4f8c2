"""The Hydra entry point experiments/abstract.py, run as a user would."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def run_app(*overrides, cwd=ROOT):
    return subprocess.run([sys.executable, str(ROOT / "experiments" / "abstract.py"), "progress=false",
                           *overrides], cwd=cwd, capture_output=True, text=True, timeout=600)


def test_overrides_and_output_schema(tmp_path, corridor_path):
    out = tmp_path / "run"
    p = run_app(f"workspace.map_file={corridor_path}", "disturbance.radius=0.2", "L_max=10", "solver=highs",
                f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr
    assert "transitions    :     78" in p.stdout and str(out / "transitions.json") in p.stdout
    assert "paper:" not in p.stdout                  # the paper's counts only beside a run on the paper map
    assert "Unable to initialize backend" not in p.stdout + p.stderr      # JAX's search for a TPU, held back
    data = json.loads((out / "transitions.json").read_text())
    assert {"cells", "edges", "stats"} <= set(data)
    assert {"id", "label", "grid", "vertices"} <= set(data["cells"][0])
    assert {"from", "to", "L", "margin", "provenance"} <= set(data["edges"][0])
    assert {"n_cells", "n_edges", "n_lps", "seconds"} <= set(data["stats"])
    assert data["stats"]["n_cells"] == 21 and data["stats"]["n_edges"] == 78
    assert (out / "transitions.npz").exists() and not (out / "edges.partial.jsonl").exists()


def test_default_pdhg_path_agrees_with_highs(tmp_path, corridor_path):
    out = tmp_path / "pdhg"
    p = run_app(f"workspace.map_file={corridor_path}", "verify=all", "solver.compilation_cache=null",
                f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr
    data = json.loads((out / "transitions.json").read_text())
    s = data["stats"]
    assert s["solver"] == "pdhg" and s["n_edges"] == 78 and s["compile_seconds"] > 0
    st = s["solver_stats"]
    assert st["highs_disagreements"] == 0 and st["certified_infeasible"] > 0
    assert st["certified_feasible"] + st["certified_infeasible"] + st["sent_to_highs"] == s["n_lps"] - s["n_translated"]
    assert s["n_translated"] > 0 and s["provenance"]["translate"] == s["n_translated"]
    prov = {e["provenance"] for e in data["edges"]}
    assert prov <= {"pdhg+highs", "highs-fallback", "highs-translate", "exact-translate"}     # every edge confirmed by HiGHS
    expected = json.loads((ROOT / "tests" / "data" / "corridor_expected.json").read_text())
    assert {(e["from"], e["to"], e["L"]) for e in data["edges"]} == \
        {tuple(e) for e in expected["cases"]["tube, r = 0.2"]["edges"]}


@pytest.mark.parametrize("overrides, match", [
    (["L_max=0"], "L_max: expected an integer in [1, 1000], got 0"),
    (["workspace.map_file=/nonexistent/map.txt"], "workspace.map_file: file '/nonexistent/map.txt' not found"),
    (["disturbance.radius=-0.1"], "disturbance.radius: expected a finite number in [0, 1e6], got -0.1"),
])
def test_bad_input_is_refused_clearly(tmp_path, overrides, match):
    p = run_app(*overrides, f"hydra.run.dir={tmp_path / 'bad'}")
    assert p.returncode == 2
    assert match in p.stderr


def test_bad_map_file_names_line_and_column(tmp_path):
    m = tmp_path / "bad.txt"
    m.write_text("...\n.%.\n")
    p = run_app(f"workspace.map_file={m}", f"hydra.run.dir={tmp_path / 'bad'}")
    assert p.returncode == 2 and "bad.txt, line 2, column 2: unknown character '%'" in p.stderr


def test_openloop_baseline_on_the_batched_path(tmp_path, corridor_path):
    out = tmp_path / "ol"
    p = run_app(f"workspace.map_file={corridor_path}", "method=openloop", "disturbance.radius=0.1",
                "solver.compilation_cache=null", f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr
    data = json.loads((out / "transitions.json").read_text())
    assert data["method"] == "openloop" and data["stats"]["solver"] == "pdhg"
    assert data["stats"]["solver_stats"]["certified_infeasible"] > 0
    expected = json.loads((ROOT / "tests" / "data" / "corridor_expected.json").read_text())
    assert {(e["from"], e["to"], e["L"]) for e in data["edges"]} == \
        {tuple(e) for e in expected["cases"]["open-loop, r = 0.1"]["edges"]}


def test_unknown_method_and_solver_are_refused(tmp_path):
    p = run_app("method.name=magic", f"hydra.run.dir={tmp_path / 'm'}")
    assert p.returncode == 2 and "method: expected one of tube, openloop, exact2d, got 'magic'" in p.stderr
    p = run_app("solver.name=cplex", f"hydra.run.dir={tmp_path / 's'}")
    assert p.returncode == 2 and "solver.name: expected one of highs, pdhg, got 'cplex'" in p.stderr


def test_the_paper_counts_only_on_the_paper_map(tmp_path):
    """The map is recognised by its content (a copy elsewhere is the paper map, another map is not), and
    the line points to the docs section that explains the difference."""
    import hashlib
    import re
    from types import SimpleNamespace

    sys.path.insert(0, str(ROOT / "experiments"))
    from abstract import PAPER_COUNTS_DOC, count_lines

    def ts(map_text: str):
        digest = hashlib.sha256(map_text.encode()).hexdigest()
        return SimpleNamespace(stats={"n_cells": 67, "n_edges": 334},
                               inputs={"workspace": {"kind": "grid", "map_file": {"path": "x.txt", "sha256": digest}}})

    paper = (ROOT / "conf" / "workspace" / "maps" / "paper.txt").read_text()
    assert count_lines(ts(paper)) == ["states         :     67   (paper: 67)",
                                      f"transitions    :    334   (paper: 655; our map differs: {PAPER_COUNTS_DOC})"]
    assert count_lines(ts(paper + "\n.")) == ["states         :     67", "transitions    :    334"]
    assert count_lines(SimpleNamespace(stats={"n_cells": 1, "n_edges": 0}, inputs=None))[0].endswith("1")
    page, anchor = PAPER_COUNTS_DOC.split("#")
    heads = re.findall(r"^#+ (.+)$", (ROOT / page).read_text(), re.M)
    assert anchor in {re.sub(r"[^a-z0-9 -]", "", h.lower()).replace(" ", "-") for h in heads}
