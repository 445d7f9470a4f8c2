"""The specification figure: avoided regions shaded, runs and plan drawn, files written."""

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection, PolyCollection  # noqa: E402
from matplotlib.patches import FancyArrowPatch  # noqa: E402

from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.analyses.plot import new_axes, plot_specification, save_figure  # noqa: E402
from tubejax.analyses.spec import plan_formula, simulate_spec  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace.gridmap import load_grid_map  # noqa: E402
from tubejax.analyses.control import SimulationRuns  # noqa: E402


def test_specification_figure(tmp_path):
    m = tmp_path / "avoid.txt"
    m.write_text("1.4.2\n.###.\n3....\n")
    d = load_grid_map(m)
    ts = build_abstraction(d, LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2)),
                           L_max=10, progress=False)
    sp = plan_formula(ts, 0, "F(l3 & F(l2)) & G(!l4)")
    sim = simulate_spec(ts, sp, SimulationRuns(n_runs=20, mode="uniform", seed=0))
    fig, ax = new_axes()
    assert plot_specification(ts, sp, sim, ax) is ax
    shaded = [c for c in ax.collections if isinstance(c, PolyCollection) and c.get_label() == "avoided region"]
    assert len(shaded) == 1 and len(shaded[0].get_paths()) == len(d.cells_with_label("4"))
    runs = [c for c in ax.collections if isinstance(c, LineCollection)]
    assert sum(len(c.get_segments()) for c in runs) == 20
    arrows = [p for p in ax.patches if isinstance(p, FancyArrowPatch)]
    assert len(arrows) == len(sp.plan.edges)
    assert "20 satisfy" in ax.get_title() and "G(!l4)" in ax.get_title()
    png, pdf = save_figure(fig, tmp_path, "spec")
    assert png.stat().st_size > 5000 and pdf.read_bytes()[:5] == b"%PDF-"
    plt.close(fig)
    fig, ax = new_axes()
    plot_specification(ts, sp, None, ax)                       # the plan alone
    assert not [c for c in ax.collections if isinstance(c, LineCollection)]
    plt.close(fig)
