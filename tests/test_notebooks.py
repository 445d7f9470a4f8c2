"""Every notebook in notebooks/ (jupytext py:percent files, or .ipynb) executes without error on
small settings, each on the sweep it is given (its own map), also from the documented command
(``jupytext --execute`` from the repository root, a relative path in the environment); the
``notebooks`` extra that ``jupyter lab notebooks/...`` needs is pinned, and so is everything the
documented headless command needs in the ``dev`` extra."""

import json
import os
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
    # the documented command (docs/howto/notebooks.md), typed at the repository root with a relative path;
    # the kernel runs in notebooks/, where that path does not exist
    rel = os.path.relpath(sweep, ROOT)
    assert not (NB_DIR / rel).exists()
    env = {k: v for k, v in os.environ.items() if k != "TUBEJAX_RADIUS_DIR"}
    env.update(TUBEJAX_SWEEP_DIR=rel, TUBEJAX_NB_SMALL="0", PWD=str(ROOT))
    executed = tmp_path / "sweep_analysis.ipynb"
    p = subprocess.run([str(Path(sys.executable).parent / "jupytext"), "--to", "ipynb", "--execute",
                        "notebooks/sweep_analysis.py", "-o", str(executed)],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-3000:]
    nb = json.loads(executed.read_text())
    out = "".join("".join(o.get("text", "")) + "".join(o.get("data", {}).get("text/plain", ""))
                  for c in nb["cells"] if c["cell_type"] == "code" for o in c.get("outputs", []))
    assert "workspaces: other_map" in out and "corridor" not in out
    assert "conservatism: not drawn (no exact2d jobs" in out      # said in a line, not drawn as an empty panel
    last = next("".join(o["data"]["text/plain"]) for o in nb["cells"][-1]["outputs"]   # jobs against the curves
                if "sweep job" in "".join(o.get("data", {}).get("text/plain", "")))
    assert "other_map" in last and last.count("tube") == 4 and last.count("openloop") == 4


def test_a_relative_path_is_found_from_where_it_was_typed(tmp_path, monkeypatch):
    """``user_path``: the current directory first, then ``$PWD`` (inherited by a kernel that runs in
    notebooks/), then the given roots; a path found nowhere is named with every place looked in."""
    from tubejax.errors import InputError
    from tubejax.files import user_path

    typed, kernel, root = (tmp_path / d for d in ("typed", "kernel", "root"))
    for d in (typed / "runs" / "a", kernel, root / "runs" / "b"):
        d.mkdir(parents=True)
    monkeypatch.chdir(kernel)
    monkeypatch.setenv("PWD", str(typed))
    assert user_path("runs/a", "TUBEJAX_SWEEP_DIR", [root]) == (typed / "runs" / "a").resolve()
    assert user_path("runs/b", "TUBEJAX_SWEEP_DIR", [root]) == (root / "runs" / "b").resolve()
    assert user_path(str(root / "runs"), "X") == (root / "runs").resolve()
    (kernel / "runs" / "a").mkdir(parents=True)                 # the current directory wins
    assert user_path("runs/a", "X", [root]) == (kernel / "runs" / "a").resolve()
    with pytest.raises(InputError, match=r"TUBEJAX_SWEEP_DIR: 'runs/c' does not exist \(looked for .*kernel"):
        user_path("runs/c", "TUBEJAX_SWEEP_DIR", [root])
    with pytest.raises(InputError, match="expected a path"):
        user_path(" ", "TUBEJAX_PAPER_DIR")


def test_the_dev_extra_holds_what_the_headless_command_needs():
    """``jupytext --to ipynb --execute`` (docs/howto/notebooks.md) executes through nbconvert."""
    extra = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]["dev"]
    reqs = {Requirement(r).name.lower(): Requirement(r) for r in extra}
    assert {"jupytext", "nbconvert", "nbclient", "ipykernel"} <= set(reqs)
    pins = dict(line.split("==") for line in (ROOT / "constraints.txt").read_text().splitlines()
                if "==" in line and not line.startswith("#"))
    for name in ("jupytext", "nbconvert"):
        assert reqs[name].specifier.contains(pins[name].strip()), name


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
