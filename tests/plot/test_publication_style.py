"""The publication style (``figures.style=paper``) and what makes large and 3-D figures readable.

Held to properties a reader checks by eye: one-line titles without run logs or cell ids, one fixed
colour per method and per kind of Z in every sweep plot (and those colours distinct and
colour-blind safe), legend entries drawn as the plot draws them, journal column sizes, arrows of a
corridor used both ways side by side, the transition graph by blocks (counted independently) and
per layer, and the 3-D view angle.
"""

from types import SimpleNamespace

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
import pytest  # noqa: E402
from matplotlib.colors import to_rgb  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import FancyArrowPatch  # noqa: E402

from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.analyses.control import SimulationRuns, plan_sequence, simulate  # noqa: E402
from tubejax.analyses.plot import (figure_style, new_axes, plot_plan_tubes_3d, plot_specification,  # noqa: E402
                                   plot_trajectories, plot_transition_graph, plot_transition_graph_layers,
                                   plot_tube, sweeps)
from tubejax.analyses.plot.graph import cell_blocks  # noqa: E402
from tubejax.analyses.plot.trajectories import RunsStyle  # noqa: E402
from tubejax.analyses.plot.layers import layer_edges, layer_of  # noqa: E402
from tubejax.analyses.plot.spec import spec_legend  # noqa: E402
from tubejax.analyses.plot.style import (COLUMN_WIDTHS, ZSHAPE_COLOURS, current_style,  # noqa: E402
                                         number, paper_style, series_colour)
from tubejax.lp.evidence.registry import method_names, series_style  # noqa: E402
from tubejax.analyses.spec import plan_formula, simulate_spec  # noqa: E402
from tubejax.inputs.app_settings import FigureSettings  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace.gridmap import parse_grid_map  # noqa: E402
from tubejax.model.workspace.voxelmap import parse_voxel_map  # noqa: E402

MAP = "1.4.2\n.###.\n3....\n"
VOXELS = "1.#.\n....\n#.#.\n---\n....\n.##.\n....\n---\n#..#\n....\n...2\n"


@pytest.fixture(scope="module")
def small():
    d = parse_grid_map(MAP, "small")
    ts = build_abstraction(d, LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2)),
                           L_max=10, progress=False)
    plan = plan_sequence(ts, d.cells_with_label("1")[0], ["2", "3"])
    return ts, plan, simulate(ts, plan, SimulationRuns(n_runs=20, mode="uniform", seed=0))


@pytest.fixture(scope="module")
def voxels():
    d = parse_voxel_map(VOXELS, "three_layers")
    ts = build_abstraction(d, LinearSystem(A=np.eye(3), B=0.5 * np.eye(3), U=box_input_set(1.0, 3), W=Ball(3, 0.05)),
                           L_max=5, progress=False)
    plan = plan_sequence(ts, d.cells_with_label("1")[0], ["2"])
    return ts, plan, simulate(ts, plan, SimulationRuns(n_runs=6, mode="uniform", seed=0))


def test_the_style_is_a_context_and_draft_outside_it():
    assert current_style() == "draft" and not paper_style()
    with figure_style("paper"):
        assert paper_style() and plt.rcParams["font.size"] == 8
        with figure_style():                       # saving inside keeps the style it is in
            assert paper_style()
    assert current_style() == "draft"
    with pytest.raises(ValueError, match="style: expected one of paper, draft"):
        figure_style("nice")


def test_paper_titles_are_one_line_without_run_logs_or_cell_ids(small):
    ts, plan, res = small
    d = ts.decomposition
    k = ts.edge_index()[plan.cells[0], plan.cells[1]]
    with figure_style("paper"):
        fig, ax = new_axes()
        plot_trajectories(d, res, ax)
        assert ax.get_title() == "20 closed-loop runs (uniform disturbances)"
        plt.close(fig)
        fig, ax = new_axes()
        plot_tube(ts, k, ax)
        e = ts.edges[k]
        assert ax.get_title() == f"tube $P_i \\to P_j$: $L = {e.L}$, margin {number(e.margin)}"
        legend = [t.get_text() for t in ax.get_legend().get_texts()]
        assert "$P_i$ (region 1)" in legend and not any("cell" in t for t in legend)
        plt.close(fig)
    fig, ax = new_axes()                               # the draft keeps the run log and the ids
    plot_trajectories(d, res, ax)
    assert "0 obstacle entries" in ax.get_title() and "\n" in ax.get_title()
    plt.close(fig)


def test_no_minus_zero():
    assert number(-0.0) == "0" and number(0.0125) == "0.0125" and number(-0.5) == "-0.5"


def test_fig6_numbers_at_most_about_ten_steps_and_always_the_last(small):
    ts, _, _ = small
    k = max(range(ts.n_edges), key=lambda i: ts.edges[i].L)
    L = ts.edges[k].L
    fig, ax = new_axes()
    plot_tube(ts, k, ax)
    numbers = sorted(int(t.get_text()) for t in ax.texts if t.get_text().isdigit())
    assert numbers[0] == 1 and numbers[-1] == L and len(numbers) <= 11
    assert all(t.get_fontsize() >= 9 for t in ax.texts if t.get_text().isdigit())
    plt.close(fig)


def test_the_plan_legend_entry_is_a_line_with_an_arrowhead_not_a_square(small):
    ts, _, _ = small
    d = ts.decomposition
    sp = plan_formula(ts, d.cells_with_label("1")[0], "F(l2) & G(!l4)")
    handles = {h.get_label().split(" (")[0]: h for h in spec_legend(sp)}
    plan = handles["plan"]
    assert isinstance(plan, Line2D) and plan.get_marker() == ">" and to_rgb(plan.get_color()) == (0, 0, 0)
    assert isinstance(handles["plan start"], Line2D) and handles["plan start"].get_linestyle() == "None"
    assert "run" not in {h.get_label() for h in spec_legend(sp, runs=False)}
    assert {"avoided region", "specified region"} <= set(handles)
    seq = plan_formula(ts, d.cells_with_label("1")[0], "F(l2)")          # nothing avoided: no such entry
    assert "avoided region" not in {h.get_label() for h in spec_legend(seq)}
    sim = simulate_spec(ts, sp, SimulationRuns(n_runs=5, mode="uniform", seed=0))
    with figure_style("paper"):
        fig, ax = new_axes()
        plot_specification(ts, sp, sim, ax)
        assert ax.get_title() == f"{sp.spec} (5 runs)"
        plt.close(fig)


def test_one_colour_per_method_and_z_kind_in_every_sweep_plot():
    rows = []
    for radius in (0.0, 0.1, 0.2):
        for L_max in (4, 7):
            for method, z in (("tube", "box"), ("tube", "diamond"), ("openloop", "box"), ("exact2d", "box")):
                rows.append(dict(method=method, zshape=z, radius=radius, L_max=L_max, workspace="/m/a.txt",
                                 system="integrator2d", n_edges=10, n_lps=100, solve_seconds=1.0 + radius))
    df = pd.DataFrame(rows)
    for plot in (sweeps.plot_edges_vs_radius, sweeps.plot_runtime, sweeps.plot_lmax):
        fig, ax = new_axes()
        plot(df, ax=ax)
        for line in ax.get_lines():
            name = line.get_label().split(" · ")[0]
            if name.startswith("tube ("):
                want = ZSHAPE_COLOURS[name[6:-1]]
            elif name in method_names():
                want = series_style(name).colour
            else:
                continue
            assert to_rgb(line.get_color()) == to_rgb(want), (plot.__name__, name)
        plt.close(fig)
    fig, (a, b) = plt.subplots(1, 2)
    sweeps.plot_edges_vs_radius(df, ax=a)
    sweeps.plot_runtime(df, ax=b)                      # the same lines, labels and colours side by side
    assert [(ln.get_label(), ln.get_color()) for ln in a.get_lines()] == \
           [(ln.get_label(), ln.get_color()) for ln in b.get_lines()]
    plt.close(fig)


def test_the_palette_is_distinct_and_has_no_pale_yellow():
    colours = [to_rgb(c) for c in [*(series_style(m).colour for m in method_names()), *ZSHAPE_COLOURS.values()]]
    assert len(set(colours)) == len(colours) - 1            # tube's own colour is the box's
    for r, g, b in colours:
        assert 0.2126 * r + 0.7152 * g + 0.0722 * b < 0.75   # enough contrast on white (no yellow)
    assert series_colour("tube", "diamond") == ZSHAPE_COLOURS["diamond"] and series_colour("exact2d") == "#000000"


def test_journal_column_sizes():
    assert FigureSettings().size == (6.0, 6.0)
    assert FigureSettings(columns=1).size == (COLUMN_WIDTHS[1], COLUMN_WIDTHS[1])
    assert FigureSettings(columns=2, width=8, height=4).size == (COLUMN_WIDTHS[2], COLUMN_WIDTHS[2] / 2)


def test_arrows_of_a_corridor_used_both_ways_lie_side_by_side(small):
    ts, _, _ = small
    x = np.concatenate([np.linspace(0.5, 4.5, 41), np.linspace(4.5, 0.5, 41)])
    path = np.stack([x, np.full_like(x, 2.5)], axis=1)
    fake = SimpleNamespace(trajectories=path[None], seed=0)
    fig, ax = new_axes()
    plot_trajectories(ts.decomposition, fake, ax, RunsStyle(density=False))
    arrows = [np.asarray(p._posA_posB) for p in ax.patches if isinstance(p, FancyArrowPatch)]
    east = [a for a in arrows if a[1, 0] > a[0, 0]]
    west = [a for a in arrows if a[1, 0] < a[0, 0]]
    assert east and west
    assert all(a[0, 1] < 2.5 for a in east) and all(a[0, 1] > 2.5 for a in west)   # each on its right-hand side
    assert min(w[0, 1] for w in west) - max(e[0, 1] for e in east) > 0.05
    plt.close(fig)


def test_a_large_graph_is_drawn_by_blocks(small):
    ts, _, _ = small
    d = ts.decomposition
    fig, ax = new_axes()
    plot_transition_graph(ts, ax, max_edges=5)
    arrows = [p for p in ax.patches if isinstance(p, FancyArrowPatch)]
    C = np.array([P.centroid[:2] for P in d.cells])
    lo, hi = d.bounds()
    block, _ = cell_blocks(C, lo, hi, 2)
    pairs = {(block[e.src], block[e.dst]) for e in ts.edges if block[e.src] != block[e.dst]}
    assert len(arrows) == len(pairs) < ts.n_edges
    assert "by blocks of" in ax.get_title()
    plt.close(fig)
    fig, ax = new_axes()
    plot_transition_graph(ts, ax)                     # small: every edge an arrow
    assert len([p for p in ax.patches if isinstance(p, FancyArrowPatch)]) == ts.n_edges
    plt.close(fig)


def test_the_3d_graph_has_a_panel_per_layer_and_marks_moves_between_layers(voxels):
    ts, plan, res = voxels
    d = ts.decomposition
    axes = plot_transition_graph_layers(ts)
    z = layer_edges(d)
    layer = layer_of(np.array([P.centroid[2] for P in d.cells]), z)
    assert len(axes) == len(z) - 1 == 3
    for k, ax in enumerate(axes):
        within = sum(1 for e in ts.edges if layer[e.src] == k and layer[e.dst] == k)
        assert len([p for p in ax.patches if isinstance(p, FancyArrowPatch)]) == within
        for gid, moves in (("up", lambda a, b: b > a), ("down", lambda a, b: b < a)):
            src = sorted({e.src for e in ts.edges if layer[e.src] == k and moves(layer[e.src], layer[e.dst])})
            marks = [c for c in ax.collections if c.get_gid() == gid]
            got = np.asarray(marks[0].get_offsets()) if marks else np.zeros((0, 2))
            want = np.array([d.cells[i].centroid[:2] for i in src]).reshape(-1, 2)
            want[:, 1] += 0.18 if gid == "up" else -0.18                  # beside the node (unit cells)
            assert np.allclose(got, want), (k, gid)     # a triangle at every source of such an edge, nowhere else
        assert (k < 2) == bool([c for c in ax.collections if c.get_gid() == "up"])
    plt.close(axes[0].figure)
    ax = plot_plan_tubes_3d(ts, plan, res, view=(10.0, 30.0))
    assert (ax.elev, ax.azim) == (10.0, 30.0)
    plt.close(ax.figure)
