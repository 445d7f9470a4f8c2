"""Issue 24: the ``figures`` section of experiments/simulate.py, paper.py and radius.py (size, dpi, Fig. 6's
edge, runs drawn), validated like every other key, and the progress bar of the simulation."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / "tests" / "data" / "tiny.txt"
sys.path.insert(0, str(ROOT / "experiments"))

from common import ConfigError, app_flags  # noqa: E402


def run(app, *overrides):
    return subprocess.run([sys.executable, str(ROOT / "experiments" / app), *overrides], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


def refused(p, expected: str):
    assert p.returncode == 2, p.stderr[-2000:]
    assert "Traceback" not in p.stderr, p.stderr[-2000:]
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("error: ")]
    assert len(lines) == 1 and expected in lines[0], p.stderr[-2000:]


# ------------------------------------------------------------------ validation (no app run)
def test_figures_section_defaults_and_shorthands():
    f = app_flags({}, simulate=True).figures
    assert (f.enabled, f.width, f.height, f.dpi, f.edge, f.runs_drawn, f.density) == (True, 6.0, 6.0, 150, None, 50,
                                                                                        True)
    assert app_flags({"figures": True}, simulate=True).figures == f
    off = app_flags({"figures": False}, simulate=True).figures
    assert not off.enabled and not off and f                  # the section is true exactly when enabled
    g = app_flags({"figures": {"dpi": 300, "edge": [3, 4], "runs_drawn": 0, "width": 3.5}}, simulate=True).figures
    assert (g.dpi, g.edge, g.runs_drawn, g.width, g.height) == (300, [3, 4], 0, 3.5, 6.0)
    r = app_flags({"figures": {"height": 5}}, figures=True).figures
    assert (r.enabled, r.width, r.height, r.dpi) == (True, 16.0, 5.0, 150)
    assert not app_flags({"figures": False}, figures=True).figures


@pytest.mark.parametrize("section, expected", [
    ("maybe", "figures: expected true or false, or a section with keys enabled, width, height, dpi, edge, "
              "runs_drawn, density, style, columns, view, got 'maybe'"),
    ({"style": "nice"}, "figures.style: expected one of paper, draft, got 'nice'"),
    ({"columns": 3}, "figures.columns: expected null (width and height as given), 1 or 2 (journal columns), got 3"),
    ({"view": [10]}, "figures.view: expected two angles [elevation, azimuth] in degrees"),
    ({"dpi": 10}, "figures.dpi: expected an integer in [20, 2400], got 10"),
    ({"dpi": 150.0}, "figures.dpi: expected an integer in [20, 2400], got 150.0"),
    ({"width": 0.5}, "figures.width: expected a finite number in [1, 100], got 0.5"),
    ({"height": "big"}, "figures.height: expected a finite number in [1, 100], got 'big'"),
    ({"edge": [1]}, "figures.edge: expected null or two cell ids [i, j] (integers >= 0), e.g. [0, 2], got [1]"),
    ({"edge": [1, -2]}, "figures.edge: expected null or two cell ids"),
    ({"edge": [True, 2]}, "figures.edge: expected null or two cell ids"),
    ({"runs_drawn": -1}, "figures.runs_drawn: expected an integer in [0, 100000], got -1"),
    ({"density": "yes"}, "figures.density: expected true or false, got 'yes'"),
    ({"enabled": 1}, "figures.enabled: expected true or false, got 1"),
    ({"runs": 5}, "figures.runs: unknown field (value 5)"),
])
def test_bad_figure_settings_name_the_key(section, expected):
    with pytest.raises(ConfigError) as exc:
        app_flags({"figures": section}, simulate=True)
    assert str(exc.value).startswith(expected), str(exc.value)


def test_radius_figures_take_no_simulation_keys():
    for key, value in (("edge", [0, 1]), ("runs_drawn", 5), ("density", True)):
        with pytest.raises(ConfigError, match=rf"^figures\.{key}: unknown field"):
            app_flags({"figures": {key: value}}, figures=True)
    with pytest.raises(ConfigError, match=r"^figures: expected true or false, or a section with keys enabled, "
                                          r"width, height, dpi, got 3"):
        app_flags({"figures": 3}, figures=True)


# ------------------------------------------------------------------ the apps
def test_simulate_app_figure_settings_and_progress(tmp_path):
    from PIL import Image

    out = tmp_path / "sim"
    p = run("simulate.py", f"workspace.map_file={TINY}", "solver=highs", "spec.sequence=[1,2]", "sim.runs=120",
            "figures.dpi=80", "figures.width=4", "figures.height=4", "figures.runs_drawn=30", f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr[-3000:]
    assert "simulating (uniform)" in p.stderr and "0/120" in p.stderr      # progress=true: a bar with a total
    for stem in ("fig5_workspace", "fig6_tube", "fig7_trajectories", "transition_graph", "fig8_specification"):
        assert round(Image.open(out / f"{stem}.png").info["dpi"][0]) == 80
        data = (out / f"{stem}.pdf").read_bytes()
        assert b"/Subtype /Type3" not in data and b"/FontFile2" in data
    edges = json.loads((out / "transitions.json").read_text())["edges"]
    src, dst = edges[-1]["from"], edges[-1]["to"]
    p2 = run("simulate.py", f"abstraction_dir={out}", "spec.sequence=[1,2]", "sim.runs=5", "progress=false",
             f"figures.edge=[{src},{dst}]", f"hydra.run.dir={tmp_path / 'edge'}")
    assert p2.returncode == 0, p2.stderr[-3000:]
    assert "simulating" not in p2.stderr and (tmp_path / "edge" / "fig6_tube.pdf").exists()
    missing = next(j for j in range(8) if j != src and not any(e["from"] == src and e["to"] == j for e in edges))
    p3 = run("simulate.py", f"abstraction_dir={out}", "spec.sequence=[1,2]", "sim.runs=5", "progress=false",
             f"figures.edge=[{src},{missing}]", f"hydra.run.dir={tmp_path / 'bad'}")
    refused(p3, f"error: figures.edge: expected a transition [i, j] of the abstraction (the abstraction has no "
                f"transition {src} -> {missing}), got [{src}, {missing}]")
    assert not (tmp_path / "bad" / "simulation.json").exists()             # refused before simulating
    p4 = run("simulate.py", f"abstraction_dir={out}", "spec.sequence=[1,2]", "sim.runs=5", "progress=false",
             "figures.edge=[0,99]", f"hydra.run.dir={tmp_path / 'bad2'}")
    refused(p4, "error: figures.edge: expected a transition [i, j] of the abstraction (cell ids are 0 .. 7), "
                "got [0, 99]")


def test_paper_app_validates_figures_before_any_work(tmp_path):
    p = run("paper.py", "progress=false", "figures.runs_drawn=-3", f"hydra.run.dir={tmp_path / 'paper'}")
    refused(p, "error: figures.runs_drawn: expected an integer in [0, 100000], got -3")
    assert not (tmp_path / "paper" / "transitions.json").exists()


def test_radius_app_figure_size(tmp_path):
    from PIL import Image

    out = tmp_path / "radius"
    p = run("radius.py", f"workspace.map_file={TINY}", "solver=highs", "L_max=4", "progress=false", "figures.dpi=50",
            "figures.width=8", "figures.height=3", f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr[-3000:]
    png = Image.open(out / "fig_radius.png")
    assert round(png.info["dpi"][0]) == 50 and png.size[0] > png.size[1]
    assert not re.search(rb"/Subtype\s*/Type3", (out / "fig_radius.pdf").read_bytes())
    refused(run("radius.py", f"workspace.map_file={TINY}", "progress=false", "+figures.edge=[0,1]",
                f"hydra.run.dir={tmp_path / 'bad'}"), "error: figures.edge: unknown field")
