"""Every notebook in notebooks/ (jupytext py:percent files, or .ipynb) executes without error on
small settings, each on the sweep it is given (its own map); the ``notebooks`` extra that
``jupyter lab notebooks/...`` needs is pinned."""

import subprocess
import sys
import tomllib
from pathlib import Path

import jupytext
import pytest
from nbclient import NotebookClient
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[1]
NB_DIR = ROOT / "notebooks"
#: Every notebook, found anew at each run: a notebook added to notebooks/ is executed without being listed.
NOTEBOOKS = sorted(NB_DIR.glob("*.py")) + sorted(NB_DIR.glob("*.ipynb"))


def execute(path: Path, monkeypatch, **env):
    monkeypatch.setenv("TUBEJAX_NB_SMALL", "1")
    for k, v in env.items():
        monkeypatch.setenv(k, v)
    nb = jupytext.read(path)
    NotebookClient(nb, timeout=900, kernel_name="python3",
                   resources={"metadata": {"path": str(path.parent)}}).execute()
    return nb


def images(nb) -> int:
    return sum("image/png" in o.get("data", {}) for c in nb.cells if c.cell_type == "code"
               for o in c.get("outputs", []))


def test_every_file_in_notebooks_is_a_notebook():
    assert len(NOTEBOOKS) >= 4
    for path in NOTEBOOKS:
        if path.suffix == ".py":                    # a stray module would be executed as a one-cell notebook
            text = path.read_text()
            assert "format_name: percent" in text or "formats: py:percent" in text, path
            assert "\n# %%" in text, path


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_executes(path, monkeypatch):
    nb = execute(path, monkeypatch)
    assert images(nb) >= 1, "the notebook drew no figure"


def test_sweep_analysis_reads_the_map_of_the_sweep_it_is_given(tmp_path, monkeypatch):
    """Not the notebook's own map: without TUBEJAX_RADIUS_DIR it solves the radius curves of the
    sweep's map (a copy of the 3x3 map under another name), never the corridor of its defaults."""
    mp = tmp_path / "other_map.txt"
    mp.write_text((ROOT / "tests" / "data" / "tiny.txt").read_text())
    sweep = tmp_path / "sweep"
    p = subprocess.run([sys.executable, str(ROOT / "experiments" / "abstract.py"), "-m", "hydra/launcher=basic",
                        "progress=false", "solver=highs", f"workspace.map_file={mp}", "L_max=3,4",
                        "disturbance.radius=0,0.2", "method=tube,openloop", f"hydra.sweep.dir={sweep}"],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    monkeypatch.delenv("TUBEJAX_RADIUS_DIR", raising=False)
    nb = execute(NB_DIR / "sweep_analysis.py", monkeypatch, TUBEJAX_SWEEP_DIR=str(sweep), TUBEJAX_NB_SMALL="0")
    out = "".join(o.get("text", "") + str(o.get("data", {}).get("text/plain", ""))
                  for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", []))
    assert "workspaces: other_map" in out and "corridor" not in out
    last = next(str(o["data"]["text/plain"]) for o in nb.cells[-1].outputs   # the jobs against the one-solve curves
                if "sweep job" in str(o.get("data", {}).get("text/plain", "")))
    assert "other_map" in last and last.count("tube") == 4 and last.count("openloop") == 4


def test_the_notebooks_extra_is_pinned():
    extra = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]["notebooks"]
    reqs = {Requirement(r).name.lower(): Requirement(r) for r in extra}
    assert {"jupyterlab", "ipywidgets"} <= set(reqs)
    pins = {}
    for line in (ROOT / "constraints.txt").read_text().splitlines():
        if "==" in line and not line.startswith("#"):
            name, version = line.split("==")
            pins[name.strip().lower().replace("_", "-")] = version.strip()
    for name, req in reqs.items():
        assert name in pins, f"{name} has no pin in constraints.txt"
        assert req.specifier.contains(pins[name]), f"{name}=={pins[name]} does not satisfy {req}"
