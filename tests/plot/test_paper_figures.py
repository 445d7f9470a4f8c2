"""Issue 24, item 6: paper-ready figures -- TrueType fonts in PDFs, Fig. 6's labels and legend, Fig. 7's
direction arrows, discrete colours for L, and many runs subsampled from the seed (not a blob)."""

import re
from types import SimpleNamespace

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.image import AxesImage  # noqa: E402
from matplotlib.patches import FancyArrowPatch  # noqa: E402

from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.analyses.control import SimulationRuns, plan_sequence, simulate  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.analyses.plot.trajectories import RUN_COLOURS, RunsStyle
from tubejax.analyses.plot import (figure_style, new_axes, plot_specification, plot_trajectories,  # noqa: E402
                                   plot_transition_graph, plot_tube, save_figure, select_runs)
from tubejax.analyses.spec import plan_formula, simulate_spec  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace.gridmap import load_grid_map  # noqa: E402

MAP = "1.4.2\n.###.\n3....\n"          # 12 cells; edges with L = 4, 7 and 10


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    m = tmp_path_factory.mktemp("map") / "small.txt"
    m.write_text(MAP)
    d = load_grid_map(m)
    ts = build_abstraction(d, LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2)),
                           L_max=10, progress=False)
    plan = plan_sequence(ts, d.cells_with_label("1")[0], ["2", "3"])
    return ts, plan


def pdf_font_subtypes(path) -> list[bytes]:
    """The ``/Subtype`` of every font dictionary of a PDF written by matplotlib (uncompressed objects)."""
    data = path.read_bytes()
    assert data[:5] == b"%PDF-"
    bodies = re.findall(rb"\d+ 0 obj\s*(<<.*?)(?:stream|endobj)", data, flags=re.DOTALL)
    fonts = [b for b in bodies if re.match(rb"<<\s*/Type\s*/Font\b", b)]
    return [re.search(rb"/Subtype\s*/(\w+)", f).group(1) for f in fonts]


def text_figure():
    fig, ax = new_axes((3, 3))
    ax.plot([0, 1], [0, 1])
    ax.set_xlabel("$x_1$")
    ax.set_title("$P_{ij}$ and text")
    return fig


# ------------------------------------------------------------------ fonts
def test_pdfs_embed_truetype_fonts_not_type3(tmp_path, small):
    before = matplotlib.rcParams["pdf.fonttype"]
    fig = text_figure()
    _, pdf = save_figure(fig, tmp_path, "fonts")
    subtypes = pdf_font_subtypes(pdf)
    assert subtypes and b"Type3" not in subtypes, subtypes
    assert b"/FontFile2" in pdf.read_bytes()                  # the TrueType program is embedded
    assert matplotlib.rcParams["pdf.fonttype"] == before      # the style applies inside save_figure only
    # the check can fail: the same figure saved outside the package's style has Type 3 fonts
    with matplotlib.rc_context({"pdf.fonttype": 3}):
        fig.savefig(tmp_path / "type3.pdf")
    assert b"Type3" in pdf_font_subtypes(tmp_path / "type3.pdf")
    with figure_style():
        assert matplotlib.rcParams["pdf.fonttype"] == 42 and matplotlib.rcParams["ps.fonttype"] == 42
    plt.close(fig)
    ts, plan = small                                          # a real figure too: the transition graph
    fig, ax = new_axes()
    plot_transition_graph(ts, ax)
    _, pdf = save_figure(fig, tmp_path, "graph")
    assert b"Type3" not in pdf_font_subtypes(pdf)
    plt.close(fig)


# ------------------------------------------------------------------ Fig. 6
def test_fig6_has_axis_labels_and_its_legend_covers_no_set(small):
    ts, _ = small
    k = int(np.argmax([e.L for e in ts.edges]))
    fig, ax = new_axes()
    plot_tube(ts, k, ax)
    assert ax.get_xlabel() == "$x_1$" and ax.get_ylabel() == "$x_2$"
    fig.canvas.draw()
    legend = ax.get_legend().get_window_extent()
    hull = next(p for p in ax.patches if p.get_label() == "$P_{ij}$")
    for patch in ax.patches:                                  # P_ij, P_i, P_j and every Q_l
        assert not legend.overlaps(patch.get_window_extent()), patch.get_label()
    assert not legend.overlaps(hull.get_window_extent())
    assert not legend.overlaps(ax.get_window_extent())        # beside the axes, not on them
    plt.close(fig)


# ------------------------------------------------------------------ Fig. 7
def fake_result(n_runs: int, steps: int = 40, seed: int = 0, bad=()):
    """Runs going left to right along y = 1.5 (plus noise): the direction of travel is +x."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.2, 4.8, steps + 1)
    X = np.stack([np.broadcast_to(t, (n_runs, steps + 1)),
                  1.5 + 0.2 * rng.standard_normal((n_runs, steps + 1))], axis=-1)
    exit_ = np.zeros(n_runs, bool)
    exit_[list(bad)] = True
    return SimpleNamespace(trajectories=X, tube_exit=exit_, obstacle_entry=np.zeros(n_runs, bool), seed=seed)


def arrow_directions(ax) -> np.ndarray:
    arrows = [p for p in ax.patches if isinstance(p, FancyArrowPatch)]
    return np.array([np.subtract(*a._posA_posB[::-1]) for a in arrows])      # posB - posA


def test_fig7_shows_the_direction_of_travel(small):
    ts, plan = small
    d = ts.decomposition
    fig, ax = new_axes()
    plot_trajectories(d, fake_result(30), ax)
    dirs = arrow_directions(ax)
    assert len(dirs) >= 3 and np.all(dirs[:, 0] > 0)          # every arrow points the way the runs go
    assert "direction of travel" in [t.get_text() for t in ax.get_legend().get_texts()]
    plt.close(fig)
    fig, ax = new_axes()                                      # reversed in time: the arrows turn round
    r = fake_result(30)
    r.trajectories = r.trajectories[:, ::-1]
    plot_trajectories(d, r, ax)
    assert np.all(arrow_directions(ax)[:, 0] < 0)
    plt.close(fig)
    fig, ax = new_axes()
    plot_trajectories(d, fake_result(30), ax, RunsStyle(arrows=False))
    assert len(arrow_directions(ax)) == 0
    plt.close(fig)
    res = simulate(ts, plan, SimulationRuns(n_runs=20, mode="uniform", seed=0))   # a real closed loop
    fig, ax = new_axes()
    plot_trajectories(d, res, ax)
    dirs = arrow_directions(ax)
    assert len(dirs) >= 3
    start = d.cells[plan.cells[0]].centroid
    first = min((p for p in ax.patches if isinstance(p, FancyArrowPatch)),
                key=lambda a: np.linalg.norm(np.asarray(a._posA_posB[0]) - start))
    A, B = map(np.asarray, first._posA_posB)
    assert np.linalg.norm(B - start) > np.linalg.norm(A - start)  # the arrow nearest the start leads away from it
    plt.close(fig)


# ------------------------------------------------------------------ transition graph
def test_transition_graph_has_one_colour_per_L(small):
    ts, _ = small
    Ls = sorted({e.L for e in ts.edges})
    assert len(Ls) >= 3
    fig, ax = new_axes()
    plot_transition_graph(ts, ax)
    arrows = [p for p in ax.patches if isinstance(p, FancyArrowPatch)]
    assert len(arrows) == ts.n_edges
    colours = {tuple(np.round(a.get_edgecolor(), 6)) for a in arrows}
    assert len(colours) == len(Ls)
    by_L = {}
    for a, e in zip(arrows, ts.edges):
        by_L.setdefault(e.L, set()).add(tuple(np.round(a.get_edgecolor(), 6)))
    assert all(len(c) == 1 for c in by_L.values())           # one colour per L value ...
    assert len({next(iter(c)) for c in by_L.values()}) == len(Ls)   # ... and different values differ
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    counts = {L: sum(e.L == L for e in ts.edges) for L in Ls}
    assert legend == [f"{L} ({counts[L]})" for L in Ls]
    assert len(fig.axes) == 1                                 # no continuous colour bar
    plt.close(fig)


# ------------------------------------------------------------------ many runs
def test_select_runs_is_seeded_and_takes_flagged_runs_first():
    a = select_runs(2000, 50, seed=3)
    assert len(a) == 50 == len(np.unique(a)) and np.all(np.diff(a) > 0) and a.max() < 2000
    assert np.array_equal(a, select_runs(2000, 50, seed=3))
    assert not np.array_equal(a, select_runs(2000, 50, seed=4))
    assert np.array_equal(select_runs(30, 50, seed=3), np.arange(30))
    assert np.array_equal(select_runs(30, None), np.arange(30))
    assert len(select_runs(30, 0)) == 0
    first = np.zeros(2000, bool)
    first[[7, 1500, 1999]] = True
    b = select_runs(2000, 50, seed=3, first=first)
    assert {7, 1500, 1999} <= set(b.tolist()) and len(b) == 50
    many = np.zeros(2000, bool)
    many[:100] = True
    c = select_runs(2000, 50, seed=3, first=many)
    assert len(c) == 50 and c.max() < 100


def drawn_lines(ax) -> int:
    return sum(len(c.get_segments()) for c in ax.collections if isinstance(c, LineCollection))


def test_fig7_with_2000_runs_draws_a_seeded_subsample_and_says_so(small):
    ts, _ = small
    d = ts.decomposition
    res = fake_result(2000, seed=11, bad=[5, 1234])
    fig, ax = new_axes()
    plot_trajectories(d, res, ax)
    assert drawn_lines(ax) == 50
    assert "50 of 2000 runs drawn (chosen by seed 11, the 2 violating first)" in ax.get_title()
    assert "shading: where all 2000 went" in ax.get_title()
    assert len([im for im in ax.get_images() if isinstance(im, AxesImage)]) == 1      # the density
    red = [c for c in ax.collections if isinstance(c, LineCollection)
           and np.allclose(c.get_edgecolor()[0][:3], matplotlib.colors.to_rgb(RUN_COLOURS["violating"]))]
    assert len(red) == 1 and len(red[0].get_segments()) == 2  # both violating runs are drawn, in vermillion
    plt.close(fig)
    fig, ax = new_axes()
    plot_trajectories(d, res, ax, RunsStyle(max_runs=120, density=False, seed=2))
    assert drawn_lines(ax) == 120 and not ax.get_images()
    assert "120 of 2000 runs drawn (chosen by seed 2" in ax.get_title() and "shading" not in ax.get_title()
    plt.close(fig)
    fig, ax = new_axes()
    plot_trajectories(d, fake_result(40), ax)
    assert drawn_lines(ax) == 40 and "all 40 runs drawn" in ax.get_title() and not ax.get_images()
    plt.close(fig)


def test_fig7_subsample_is_the_same_for_the_same_seed(small):
    ts, _ = small
    res = fake_result(500, seed=4)

    def segments(**kw):
        fig, ax = new_axes()
        plot_trajectories(ts.decomposition, res, ax, RunsStyle(**kw))
        segs = np.concatenate([np.stack(c.get_segments()) for c in ax.collections if isinstance(c, LineCollection)])
        plt.close(fig)
        return segs

    assert np.array_equal(segments(), segments())
    assert not np.array_equal(segments(), segments(seed=5))


def test_fig8_subsamples_runs_too(tmp_path):
    m = tmp_path / "avoid.txt"
    m.write_text(MAP)
    d = load_grid_map(m)
    ts = build_abstraction(d, LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2)),
                           L_max=10, progress=False)
    sp = plan_formula(ts, 0, "F(l3 & F(l2)) & G(!l4)")
    sim = simulate_spec(ts, sp, SimulationRuns(n_runs=300, mode="uniform", seed=0))
    fig, ax = new_axes()
    plot_specification(ts, sp, sim, ax, max_runs=25)
    assert drawn_lines(ax) == 25
    assert "25 of 300 runs drawn (chosen by seed 0)" in ax.get_title() and ax.get_images()
    _, pdf = save_figure(fig, tmp_path, "fig8")
    assert b"Type3" not in pdf_font_subtypes(pdf)
    plt.close(fig)
