"""Figures are written as non-empty PNG + PDF files."""

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from tubejax.analyses.control import SimulationRuns, plan_sequence, simulate  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.analyses.plot import (new_axes, plot_transition_graph, plot_trajectories, plot_tube,  # noqa: E402
                                   plot_workspace, save_figure)
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace.gridmap import load_grid_map  # noqa: E402

PAPER_MAP = "conf/workspace/maps/paper.txt"
CORRIDOR = "/work/shared/validation/corridor.txt"


@pytest.fixture(scope="module")
def corridor():
    from tubejax.abstraction import build_abstraction
    d = load_grid_map(CORRIDOR)
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    return build_abstraction(d, s, L_max=10, progress=False)


def check_written(paths):
    png, pdf = paths
    assert png.suffix == ".png" and pdf.suffix == ".pdf"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 2000
    assert pdf.read_bytes()[:5] == b"%PDF-" and pdf.stat().st_size > 1000


def test_workspace_figure(tmp_path):
    from pathlib import Path
    here = Path(__file__).resolve().parents[2]
    d = load_grid_map(here / PAPER_MAP)
    fig, ax = new_axes()
    assert plot_workspace(d, ax, cell_ids=True) is ax
    texts = {t.get_text() for t in ax.texts}
    assert {"1", "2", "3", "4", "5", "6"} <= texts
    assert len(ax.patches) >= 1                       # the obstacles
    check_written(save_figure(fig, tmp_path, "fig5_workspace"))
    plt.close(fig)


def test_tube_figure(corridor, tmp_path):
    ts = corridor
    k = int(np.argmax([e.L for e in ts.edges]))
    ax = plot_tube(ts, k)
    assert len(ax.patches) == 3 + ts.edges[k].L        # P_ij, P_i, P_j, Q_1..Q_L
    check_written(save_figure(ax, tmp_path, "fig6_tube"))   # an Axes is accepted too
    plt.close(ax.figure)
    fig, ax = new_axes()
    plot_tube(ts, 0, ax, workspace=True)
    check_written(save_figure(fig, tmp_path / "sub", "fig6_tube_ws"))
    plt.close(fig)


def test_trajectories_and_graph(corridor, tmp_path):
    ts = corridor
    d = ts.decomposition
    plan = plan_sequence(ts, d.cells_with_label("1")[0], ["2", "1"])
    res = simulate(ts, plan, SimulationRuns(n_runs=300, mode="uniform", seed=0))   # shapes as in test_simulate
    fig, ax = new_axes()
    plot_trajectories(d, res, ax)
    assert len(ax.collections) >= 2                   # cells + trajectories
    assert "0 obstacle entries" in ax.get_title()
    check_written(save_figure(fig, tmp_path, "fig7_trajectories"))
    plt.close(fig)
    fig, ax = new_axes()
    plot_transition_graph(ts, ax)
    assert len(ax.patches) >= ts.n_edges
    check_written(save_figure(fig, tmp_path, "transition_graph"))
    plt.close(fig)
