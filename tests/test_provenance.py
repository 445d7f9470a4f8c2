"""Every output records the tubejax version, the git commit (and whether the tree was dirty) and the
command line; files with and without that record load and verify alike."""

import json
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import jax
import pytest

from tubejax.transitions import provenance as prov
from tubejax.abstraction import build_abstraction
from tubejax.transitions.transition_system import TransitionSystem
from tubejax.verify.verifier import verify_directory
from tubejax.model.workspace import parse_grid_map

jax.config.update("jax_enable_x64", True)

ROOT = Path(__file__).resolve().parents[1]
GIT = shutil.which("git")


def _git(cwd, *args):
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, check=True,
                          env={"GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@t", "GIT_COMMITTER_NAME": "t",
                               "GIT_COMMITTER_EMAIL": "t@t", "HOME": str(cwd), "PATH": "/usr/bin:/bin"}).stdout


def test_the_record():
    rec = prov.provenance(["experiments/abstract.py", "L_max=5", "workspace.map_file=my map.txt"])
    assert list(rec) == list(prov.PROVENANCE_KEYS)
    assert rec["tubejax_version"] == prov.package_version()
    assert rec["command"] == "experiments/abstract.py L_max=5 'workspace.map_file=my map.txt'"
    assert prov.provenance()["command"] == shlex.join(sys.argv)
    json.dumps(rec)


@pytest.mark.skipif(GIT is None or not (ROOT / ".git").exists(), reason="needs git and a checkout")
def test_this_checkout_is_recorded():
    commit, dirty = prov.git_state()
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True).stdout
    assert commit == head.strip() and len(commit) == 40 and isinstance(dirty, bool)


def test_not_a_checkout(tmp_path):
    (tmp_path / "pkg").mkdir()
    assert prov.git_state(tmp_path) == (None, None)


@pytest.mark.skipif(GIT is None, reason="needs git")
def test_commit_and_dirty_state_of_a_repository(tmp_path):
    _git(tmp_path, "init", "-q")
    (tmp_path / "a.py").write_text("x = 1\n")
    _git(tmp_path, "add", "a.py")
    _git(tmp_path, "commit", "-q", "-m", "one")
    head = _git(tmp_path, "rev-parse", "HEAD").strip()
    prov.git_state.cache_clear()
    assert prov.git_state(tmp_path) == (head, False)
    (tmp_path / "new.txt").write_text("untracked files do not count\n")
    prov.git_state.cache_clear()
    assert prov.git_state(tmp_path) == (head, False)
    (tmp_path / "a.py").write_text("x = 2\n")
    prov.git_state.cache_clear()
    assert prov.git_state(tmp_path) == (head, True)
    inner = tmp_path / "sub"                         # inside a repository, but not its top level
    inner.mkdir()
    assert prov.git_state(inner) == (None, None)
    prov.git_state.cache_clear()


def test_version_falls_back_to_pyproject(monkeypatch):
    def missing(name):
        raise prov.metadata.PackageNotFoundError(name)

    monkeypatch.setattr(prov.metadata, "version", missing)
    with open(ROOT / "pyproject.toml", "rb") as f:
        assert prov.package_version() == tomllib.load(f)["project"]["version"]
    monkeypatch.setattr(prov, "_SOURCE_ROOT", Path("/nonexistent"))
    assert prov.package_version() == "unknown"


def test_stamp():
    doc = {"runs": 3}
    nested = prov.stamp(doc)
    assert nested["runs"] == 3 and list(nested["provenance"]) == list(prov.PROVENANCE_KEYS) and doc == {"runs": 3}
    flat = prov.stamp(doc, flat=True)
    assert set(flat) == {"runs", *prov.PROVENANCE_KEYS}
    assert prov.stamp({"command": "kept"}, flat=True)["command"] == "kept"
    assert prov.stamp({"provenance": {"kept": 1}}) == {"provenance": {"kept": 1}}
    assert prov.stamp([1, 2]) == [1, 2]


@pytest.fixture(scope="module")
def saved(tmp_path_factory, paper_system):
    d = tmp_path_factory.mktemp("prov")
    ts = build_abstraction(parse_grid_map("1..\n.#.\n..2\n"), paper_system(0.1), L_max=4, progress=False)
    ts.save(d)
    return d


def test_transitions_files_record_it_and_load_with_or_without_it(saved):
    data = json.loads((saved / "transitions.json").read_text())
    assert data["provenance"] == prov.provenance()
    assert TransitionSystem.load(saved).n_edges > 0
    rep = verify_directory(saved, trust_file_data=True)
    assert rep.ok, rep.findings
    del data["provenance"]                           # a file written before provenance existed
    (saved / "transitions.json").write_text(json.dumps(data))
    assert TransitionSystem.load(saved).n_edges > 0
    assert verify_directory(saved, trust_file_data=True).ok
    data["provenance"] = "not an object"
    (saved / "transitions.json").write_text(json.dumps(data))
    with pytest.raises(ValueError, match="field 'provenance'"):
        TransitionSystem.load(saved)


def test_the_apps_writer(tmp_path):
    sys.path.insert(0, str(ROOT / "experiments"))
    try:
        from common import write_json
    finally:
        sys.path.remove(str(ROOT / "experiments"))
    write_json(tmp_path / "metrics.json", {"n_edges": 3})
    write_json(tmp_path / "simulation.json", {"runs": 3})
    write_json(tmp_path / "list.json", [1])
    row = json.loads((tmp_path / "metrics.json").read_text())
    assert row["n_edges"] == 3 and all(k in row for k in prov.PROVENANCE_KEYS) and "provenance" not in row
    assert json.loads((tmp_path / "simulation.json").read_text())["provenance"] == prov.provenance()
    assert json.loads((tmp_path / "list.json").read_text()) == [1]


def test_an_app_run_records_it(tmp_path):
    out = tmp_path / "run"
    p = subprocess.run([sys.executable, str(ROOT / "experiments" / "abstract.py"), "progress=false", "solver=highs",
                        "workspace=tiny", "L_max=4", f"hydra.run.dir={out}"], cwd=ROOT, capture_output=True,
                       text=True, timeout=600)
    assert p.returncode == 0, p.stderr
    row = json.loads((out / "metrics.json").read_text())
    doc = json.loads((out / "transitions.json").read_text())
    for rec in (row, doc["provenance"]):
        assert rec["tubejax_version"] == prov.package_version() and rec["git_commit"] == prov.git_state()[0]
        assert "abstract.py" in rec["command"] and "L_max=4" in rec["command"]
    v = subprocess.run([sys.executable, "-m", "tubejax", "verify", str(out), "--quiet"], cwd=ROOT,
                       capture_output=True, text=True, timeout=600)
    assert v.returncode == 0, v.stdout + v.stderr
