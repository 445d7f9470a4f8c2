"""Issue 48: what ``verify`` prints as OK holds with ``metrics.json`` deleted, and says what it checked.

Runs ``experiments/abstract.py`` on the tiny map (HiGHS, L_max = 3) for an honest run (W a ball of
radius 0.05, U the unit box, min_margin 0.01) and for three runs of an easier problem (W of radius
0.01; U the box of bound 2; min_margin 0). A forger who passes an easier run's files off as the
honest run's (its own record and copies consistent, ``metrics.json`` deleted) is caught by the run's
config saved beside the files; one who rewrites every copy of the config has an honest run of the
easier problem, and ``verify`` says which problem its edges are proved for. Deleted edges are a
completeness claim: plain ``verify`` says it did not check completeness, ``--complete`` finds them.
Equivalent files (a margin moved within the check's tolerance, the metrics' edges reordered, run
statistics edited) pass.
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tubejax.__main__ import main as cli
from tubejax.transitions.file_format import sha256_file
from tubejax.transitions.transition_system import TransitionSystem
from tubejax.verify.verifier import verify_directory

ROOT = Path(__file__).resolve().parents[1]
BASE = ["workspace=tiny", "solver=highs", "L_max=3", "progress=false"]
RUNS = {"honest": ["disturbance.radius=0.05", "min_margin=0.01"],
        "small_w": ["disturbance.radius=0.01", "min_margin=0.01"],
        "big_u": ["disturbance.radius=0.05", "min_margin=0.01", "system.U.bound=2.0"],
        "no_margin": ["disturbance.radius=0.05", "min_margin=0.0"]}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("independence")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    for name, args in RUNS.items():
        p = subprocess.run([sys.executable, str(ROOT / "experiments" / "abstract.py"), *BASE, *args,
                            f"hydra.run.dir={root / name}"], cwd=ROOT, env=env, capture_output=True, text=True,
                           timeout=300)
        assert p.returncode == 0, p.stderr[-2000:]
    return root


def _forge(runs: Path, tmp: Path, files_of: str, config_of: str = "honest") -> Path:
    """The transitions files of run ``files_of`` beside the saved config of run ``config_of``, no metrics.json."""
    d = tmp / f"{files_of}-as-{config_of}"
    d.mkdir()
    for f in ("transitions.json", "transitions.npz"):
        shutil.copy(runs / files_of / f, d / f)
    shutil.copytree(runs / config_of / ".hydra", d / ".hydra")
    return d


def _edit_json(d: Path, edit) -> None:
    jpath = d / "transitions.json"
    data = json.loads(jpath.read_text())
    edit(data)
    data["npz_sha256"] = sha256_file(d / "transitions.npz")
    jpath.write_text(json.dumps(data))


def test_the_honest_run_says_what_it_checked_with_and_without_metrics(runs, tmp_path, capsys):
    rep = verify_directory(runs / "honest")
    assert rep.ok, rep.findings
    assert rep.headline == "edges proved; completeness not checked (run --complete)"
    notes = "\n".join(rep.notes)
    assert "W ball radius 0.05; U box bound 1" in notes and "min_margin 0.01" in notes
    assert "agrees with the run's config (transitions.json stats.config and .hydra/config.yaml)" in notes
    assert "metrics.json: its edges, counts and settings agree" in notes
    d = tmp_path / "bare"
    shutil.copytree(runs / "honest", d)
    (d / "metrics.json").unlink()
    assert cli(["verify", str(d), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("verify OK: edges proved; completeness not checked (run --complete)\n")
    assert "metrics.json: none beside the files" in out
    rep = verify_directory(d, complete=True)
    assert rep.ok and rep.headline.startswith("edges proved; complete")


@pytest.mark.parametrize("files_of, field, said, recorded, stated", [
    ("small_w", "disturbance", "'radius': 0.05", "'radius': 0.01", "W ball radius 0.01;"),
    ("big_u", "system.U", "'bound': 1.0", "'bound': 2.0", "U box bound 2;"),
    ("no_margin", "min_margin", "0.01", "0.0", "min_margin 0;"),
])
def test_an_easier_problem_passed_off_as_the_run_is_refused_without_metrics(runs, tmp_path, files_of, field, said,
                                                                            recorded, stated):
    d = _forge(runs, tmp_path, files_of)                   # the file's own stats.config is the easier run's
    rep = verify_directory(d)
    hit = [f for f in rep.findings if ".hydra/config.yaml" in f and f": {field} is " in f]
    assert not rep.ok and hit, rep.findings
    assert said in hit[0] and recorded in hit[0]
    # the copy inside the file rewritten to the honest config: it is compared too
    honest = json.loads((runs / "honest" / "transitions.json").read_text())["stats"]["config"]
    shutil.rmtree(d / ".hydra")
    _edit_json(d, lambda data: data["stats"].update(config=honest))
    rep = verify_directory(d)
    assert not rep.ok and any("stats.config" in f and f": {field} is " in f for f in rep.findings), rep.findings
    # every copy rewritten: an honest run of the easier problem, and verify says which problem
    (tmp_path / "x").mkdir()
    rep = verify_directory(_forge(runs, tmp_path / "x", files_of, config_of=files_of))
    assert rep.ok and stated in "\n".join(rep.notes), rep.notes


def test_without_any_saved_config_verify_says_the_problem_is_the_records(runs, tmp_path):
    d = _forge(runs, tmp_path, "small_w")
    shutil.rmtree(d / ".hydra")
    _edit_json(d, lambda data: data["stats"].pop("config"))
    rep = verify_directory(d)
    assert rep.ok, rep.findings
    notes = "\n".join(rep.notes)
    assert "no saved run config to compare the inputs record with" in notes and "W ball radius 0.01" in notes


@pytest.mark.parametrize("keep", [lambda edges: edges[1:], lambda edges: []])
def test_deleted_edges_are_not_called_complete(runs, tmp_path, keep):
    d = tmp_path / "cut"
    shutil.copytree(runs / "honest", d)
    (d / "metrics.json").unlink()
    ts = TransitionSystem.load(d)
    n = ts.n_edges
    kept = keep(list(range(n)))
    ts.edges, ts.tubes = [ts.edges[k] for k in kept], [ts.tubes[k] for k in kept]
    ts.stats["n_edges"] = ts.n_edges
    ts.save(d)
    rep = verify_directory(d)
    assert rep.ok and rep.n_edges == len(kept) < n
    assert "completeness not checked (run --complete)" in rep.headline
    rep = verify_directory(d, complete=True)
    assert not rep.ok and any("missing from the file" in f for f in rep.findings)


def test_equivalent_metrics_pass_and_a_false_count_does_not(runs, tmp_path):
    d = tmp_path / "eq"
    shutil.copytree(runs / "honest", d)
    m = json.loads((d / "metrics.json").read_text().replace("NaN", "null"))
    m.update(edges=m["edges"][::-1], solver="pdhg", n_lps=m["n_lps"] + 7, seconds=99.0, compile_seconds=3.0)
    (d / "metrics.json").write_text(json.dumps(m))
    _edit_json(d, lambda data: (data["edges"][0].update(margin=data["edges"][0]["margin"] + 5e-8),
                                data["stats"].update(n_lps=1, seconds=0.5, solver_stats={"x": 1})))
    rep = verify_directory(d)
    assert rep.ok, rep.findings
    (d / "metrics.json").write_text(json.dumps(dict(m, n_edges=m["n_edges"] - 1)))
    rep = verify_directory(d)
    assert not rep.ok and any("field 'n_edges'" in f for f in rep.findings)
    (d / "metrics.json").write_text(json.dumps(dict(m, edges=m["edges"][1:])))
    assert any("field 'edges' differs" in f for f in verify_directory(d).findings)
