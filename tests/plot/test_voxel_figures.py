"""Figures of 3-D workspaces (voxel maps): one panel per layer for Figs. 5, 7 and 8, the tubes in 3-D
for Fig. 6 and ``fig9_tubes3d``, instead of a projection onto (x_1, x_2) that overlays the layers."""

import sys
from pathlib import Path
from types import SimpleNamespace

import jax

jax.config.update("jax_enable_x64", True)

import matplotlib  # noqa: E402

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from matplotlib.collections import LineCollection, PolyCollection  # noqa: E402
from matplotlib.patches import ArrowStyle, FancyArrowPatch, Polygon as MplPolygon  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.analyses.control import SimulationRuns, plan_sequence, simulate  # noqa: E402
from tubejax.analyses.plot.trajectories import RUN_COLOURS, RunsStyle
from tubejax.analyses.plot import (is_layered, plot_plan_tubes_3d, plot_specification_layers,  # noqa: E402
                                   plot_trajectories_layers, plot_tube_3d, plot_workspace_layers, save_figure)
from tubejax.analyses.plot.layers import crossings, layer_edges, layer_of, layer_slice, slab_pieces  # noqa: E402
from tubejax.analyses.plot.view3d import facets, figures_3d  # noqa: E402
from tubejax.analyses.spec import plan_formula, simulate_spec  # noqa: E402
from tubejax.model.geometry import Ball, Polytope  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace import box_grid  # noqa: E402
from tubejax.model.workspace.gridmap import parse_grid_map  # noqa: E402
from tubejax.model.workspace.voxelmap import parse_voxel_map  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
#: Three layers of 3 x 4 voxels; obstacle boxes (runs of '#' along a row): 3, 1 and 2 per layer.
MAP = "1.#.\n....\n#.#.\n---\n....\n.##.\n....\n---\n#..#\n....\n...2\n"
OBSTACLES_PER_LAYER = [3, 1, 2]


@pytest.fixture(scope="module")
def voxels():
    d = parse_voxel_map(MAP, "three_layers")
    ts = build_abstraction(d, LinearSystem(A=np.eye(3), B=0.5 * np.eye(3), U=box_input_set(1.0, 3), W=Ball(3, 0.05)),
                           L_max=5, progress=False)
    plan = plan_sequence(ts, d.cells_with_label("1")[0], ["2"])
    res = simulate(ts, plan, SimulationRuns(n_runs=30, mode="uniform", seed=0))
    return ts, plan, res


def black_patches(ax):
    return [p for p in ax.patches if isinstance(p, MplPolygon) and p.get_facecolor()[:3] == (0.0, 0.0, 0.0)]


def line_points(ax) -> np.ndarray:
    """All vertices of the axes' LineCollections, shape (k, 2)."""
    segs = [s for c in ax.collections if isinstance(c, LineCollection) for s in c.get_segments()]
    return np.vstack(segs) if segs else np.zeros((0, 2))


def markers(ax, marker):
    return sum(len(ln.get_xdata()) for ln in ax.lines if ln.get_marker() == marker)


# ------------------------------------------------------------------ the layers
def test_a_voxel_map_is_layered_and_its_layers_are_its_floors():
    d = parse_voxel_map(MAP)
    assert is_layered(d) and np.array_equal(layer_edges(d), [0.0, 1.0, 2.0, 3.0])
    assert not is_layered(parse_grid_map("1.#\n..2\n"))                      # 2-D: the 2-D figures
    grid = np.asarray(d.grid)
    for k in range(3):
        ids, sl, obstacles = layer_slice(d, k, layer_edges(d))
        assert np.array_equal(ids, np.flatnonzero(grid[:, 0] == k))           # the cells of layer k, no other
        assert sl.dim == 2 and len(sl.cells) == len(ids) and len(obstacles) == OBSTACLES_PER_LAYER[k]
    assert list(layer_of([0.0, 0.5, 1.0, 2.99, 3.0, 7.0, -1.0], layer_edges(d))) == [0, 0, 1, 2, 2, 2, 0]
    # a 3-D box grid with an obstacle through two of its three layers and uneven layers
    b = box_grid([0, 0, 0], [2, 2, 3], [2, 2, 3], obstacles=[((1, 1, 0), (2, 2, 2))])
    assert is_layered(b) and np.array_equal(layer_edges(b), [0.0, 1.0, 2.0, 3.0])
    assert [len(layer_slice(b, k, layer_edges(b))[2]) for k in range(3)] == [1, 1, 0]


def test_paths_are_cut_where_they_cross_a_layer_boundary():
    edges = np.array([0.0, 1.0, 2.0, 3.0])
    path = np.array([[0.5, 0.5, 0.5], [1.5, 0.5, 0.5], [1.5, 1.5, 1.5], [2.5, 1.5, 2.5]])
    p0, = slab_pieces(path, 0.0, 1.0, 0, edges)
    p1, = slab_pieces(path, 1.0, 2.0, 1, edges)
    p2, = slab_pieces(path, 2.0, 3.0, 2, edges)
    assert np.allclose(p0, [[0.5, 0.5, 0.5], [1.5, 0.5, 0.5], [1.5, 1.0, 1.0]])
    assert np.allclose(p1, [[1.5, 1.0, 1.0], [1.5, 1.5, 1.5], [2.0, 1.5, 2.0]])
    assert np.allclose(p2, [[2.0, 1.5, 2.0], [2.5, 1.5, 2.5]])
    c = crossings(path, edges)
    assert [(k, up) for k, _, up in c] == [(1, True), (2, True)] and np.allclose(c[0][1], [1.5, 1.0, 1.0])
    assert [(k, up) for k, _, up in crossings(path[::-1], edges)] == [(2, False), (1, False)]
    jump = np.array([[0.0, 0.0, 0.5], [0.0, 3.0, 2.0]])                       # two boundaries in one step
    assert [k for k, _, _ in crossings(jump, edges)] == [1, 2]
    assert len(slab_pieces(jump, 1.0, 2.0, 1, edges)) == 1
    broken = path.copy()
    broken[1] = np.nan                                                        # segments with a NaN end: left out
    assert slab_pieces(broken, 0.0, 1.0, 0, edges) == [] and len(slab_pieces(broken, 1.0, 2.0, 1, edges)) == 1
    leaves = np.array([[0.5, 0.5, 0.5], [0.5, 0.5, 1.5], [1.5, 0.5, 0.5]])   # leaves layer 0 and comes back
    assert len(slab_pieces(leaves, 0.0, 1.0, 0, edges)) == 2 and len(slab_pieces(leaves, 1.0, 2.0, 1, edges)) == 1


def test_faces_of_polytopes_in_3d():
    box = Polytope.box((0, 0, 0), (1, 2, 3))
    F = facets(box)
    assert len(F) == 6 and all(len(f) == 4 for f in F)
    for f in F:                                                               # each face a planar ring in order
        V = box.vertices[f]
        edges = np.linalg.norm(np.diff(np.vstack([V, V[:1]]), axis=0), axis=1)
        assert np.all(edges > 0) and np.ptp(V, axis=0).min() == 0.0
        assert not np.isclose(edges, np.linalg.norm(V[2] - V[0])).any()      # no diagonal: the ring goes round
    octa = Polytope.from_vertices(np.vstack([np.eye(3), -np.eye(3)]))
    assert len(facets(octa)) == 8 and all(len(f) == 3 for f in facets(octa))


# ------------------------------------------------------------------ Fig. 5
def test_each_layer_panel_holds_exactly_its_layers_obstacles_cells_and_labels(voxels, tmp_path):
    ts, _, _ = voxels
    d = ts.decomposition
    axes = plot_workspace_layers(d)
    assert len(axes) == 3 and len({id(ax.figure) for ax in axes}) == 1
    grid = np.asarray(d.grid)
    for k, ax in enumerate(axes):
        obs = black_patches(ax)
        assert len(obs) == OBSTACLES_PER_LAYER[k]
        want = sorted(tuple(np.r_[o.bounding_box()[0][:2], o.bounding_box()[1][:2]]) for o in d.obstacles
                      if o.bounding_box()[0][2] == k)
        got = sorted(tuple(np.r_[p.get_xy().min(0), p.get_xy().max(0)]) for p in obs)
        assert np.allclose(got, want)
        cells = [c for c in ax.collections if isinstance(c, PolyCollection)]
        assert len(cells) == 1 and len(cells[0].get_paths()) == int(np.sum(grid[:, 0] == k))
        assert f"layer {k + 1}" in ax.get_title() and f"[{k}, {k + 1}]" in ax.get_title()
        assert ax.get_xlim()[0] < 0 < 4 < ax.get_xlim()[1]                    # every panel shows the whole floor
    assert [t.get_text() for t in axes[0].texts] == ["1"] and not axes[1].texts
    assert [t.get_text() for t in axes[2].texts] == ["2"]
    png, pdf = save_figure(axes[0].figure, tmp_path, "fig5_workspace")
    assert png.stat().st_size > 5000 and pdf.read_bytes()[:5] == b"%PDF-"
    plt.close(axes[0].figure)
    with pytest.raises(ValueError, match="one axes per layer"):
        plot_workspace_layers(d, axes[:2])


def test_a_layer_without_free_cells_shows_its_obstacles():
    d = parse_voxel_map("1.\n..\n---\n##\n##\n---\n.2\n..\n")                # a slab between two floors
    axes = plot_workspace_layers(d)
    assert [len(black_patches(ax)) for ax in axes] == [0, 2, 0]
    assert [len(ax.collections) for ax in axes] == [1, 0, 1]
    assert axes[1].get_xlim() == axes[0].get_xlim() and axes[1].get_ylim() == axes[0].get_ylim()
    plt.close(axes[0].figure)


# ------------------------------------------------------------------ Fig. 7
def test_figures_3d_draw_the_runs_their_style_chooses(voxels):
    ts, plan, res = voxels
    figs = dict(figures_3d(ts, plan, res, plan.edges[0], runs=RunsStyle(max_runs=3, density=False)))
    assert list(figs) == ["fig5_workspace", "fig6_tube", "fig7_trajectories", "fig9_tubes3d", "transition_graph"]
    assert "3 of 30 runs drawn" in figs["fig7_trajectories"]._suptitle.get_text()
    assert "shading" not in figs["fig7_trajectories"]._suptitle.get_text()
    for fig in figs.values():
        plt.close(fig)


def test_fig7_draws_each_state_only_in_the_panel_of_its_layer(voxels):
    ts, _, _ = voxels
    d = ts.decomposition
    low = np.array([[0.5, 2.5, 0.5], [1.5, 2.5, 0.4], [1.5, 1.5, 0.6], [3.5, 1.5, 0.5]])      # stays in layer 0
    climb = np.array([[0.5, 1.5, 0.5], [1.25, 1.25, 0.75], [3.5, 0.5, 1.5], [3.6, 1.6, 2.5]])  # layers 0 -> 1 -> 2
    fake = SimpleNamespace(trajectories=np.stack([low, climb]), seed=0)
    axes = plot_trajectories_layers(d, fake, runs=RunsStyle(max_runs=None))
    for k, ax in enumerate(axes):
        pts = line_points(ax)
        for X in (low, climb):
            for x in X:
                drawn = np.isclose(pts, x[:2]).all(1).any()
                assert drawn == (int(x[2]) == k), (k, x)                     # in panel k exactly when in layer k
    assert len(line_points(axes[0])) == 4 + 3 and len(line_points(axes[1])) == 3 and len(line_points(axes[2])) == 2
    assert [markers(ax, "^") for ax in axes] == [1, 2, 1] and not any(markers(ax, "v") for ax in axes)
    greens = [sum(len(ln.get_xdata()) for ln in ax.lines if ln.get_color() == RUN_COLOURS["start"]) for ax in axes]
    purples = [sum(len(ln.get_xdata()) for ln in ax.lines if ln.get_color() == RUN_COLOURS["end"]) for ax in axes]
    assert greens == [2, 0, 0] and purples == [1, 0, 1]                       # start and end dots in their layers
    assert axes[0].figure._suptitle.get_text() == "all 2 runs drawn"
    labels = [t.get_text() for t in axes[0].figure.legends[0].get_texts()]
    assert labels == ["start", "end", "direction of travel", "moves up a layer"]
    plt.close(axes[0].figure)


def test_fig7_of_a_simulation_says_what_the_2d_figure_says(voxels, tmp_path):
    ts, plan, res = voxels
    d = ts.decomposition
    axes = plot_trajectories_layers(d, res, runs=RunsStyle(max_runs=10))
    title = axes[0].figure._suptitle.get_text()
    assert "30 runs (uniform): 0 obstacle entries, 0 tube exits" in title and "10 of 30 runs drawn" in title
    assert sum(len(c.get_segments()) for ax in axes for c in ax.collections if isinstance(c, LineCollection)) >= 10
    assert [len(ax.images) for ax in axes] == [1, 1, 1]                       # the shading, per layer
    start = layer_of(d.cells[plan.cells[0]].centroid[2], layer_edges(d))
    for k, ax in enumerate(axes):                                             # runs start in the start cell's layer
        assert any(ln.get_color() == RUN_COLOURS["start"] for ln in ax.lines) == (k == start)
    check = save_figure(axes[0].figure, tmp_path, "fig7_trajectories")
    assert check[0].stat().st_size > 5000
    plt.close(axes[0].figure)


# ------------------------------------------------------------------ Fig. 8
def test_fig8_draws_regions_runs_and_the_plan_in_their_layers(voxels):
    ts, _, _ = voxels
    d = ts.decomposition
    sp = plan_formula(ts, d.cells_with_label("1")[0], "F(l2)")
    sim = simulate_spec(ts, sp, SimulationRuns(n_runs=12, mode="uniform", seed=0))
    axes = plot_specification_layers(ts, sp, sim)
    goal = [[c for c in ax.collections if c.get_label() == "specified region"] for ax in axes]
    assert [len(g) for g in goal] == [0, 0, 1] and len(goal[2][0].get_paths()) == 1
    C = np.array([d.cells[c].centroid for c in sp.plan.cells])
    heads = sum(1 for ax in axes for p in ax.patches if isinstance(p, FancyArrowPatch)
                and isinstance(p.get_arrowstyle(), ArrowStyle.CurveFilledB))
    moved = np.linalg.norm(np.diff(C[:, :2], axis=0), axis=1) > 1e-9
    assert heads == int(moved.sum())                                          # one arrowhead per step across the floor
    changes = int(np.sum(np.abs(np.diff(np.round(C[:, 2] - 0.5)))))
    assert changes >= 2                                                        # the plan climbs two layers
    black = sum(1 for ax in axes for ln in ax.lines if ln.get_marker() in ("^", "v") and ln.get_color() == "black")
    assert black == 2 * changes                                               # each move marked in both panels
    title = axes[0].figure._suptitle.get_text()
    assert "F(l2)" in title and "12 satisfy" in title
    plt.close(axes[0].figure)


# ------------------------------------------------------------------ Fig. 6 and fig9 in 3-D
def solids(ax, gid):
    return [c for c in ax.collections if isinstance(c, Poly3DCollection) and c.get_gid() == gid]


def test_fig6_in_3d_has_one_solid_per_tube_set(voxels, tmp_path):
    ts, plan, _ = voxels
    k = plan.edges[0]
    e = ts.edges[k]
    ax = plot_tube_3d(ts, k)
    assert ax.name == "3d"
    tubes = solids(ax, "tube")
    assert len(tubes) == e.L and len(solids(ax, "start")) == len(solids(ax, "target")) == 1
    q = ts.tubes[k].vertices(ts.z_of(e.src, e.dst), ts.decomposition.cells[e.src])
    for l, poly in enumerate(tubes, start=1):                                # Q_l's faces are at Q_l's vertices
        V = np.asarray(poly._faces).reshape(-1, 3)                           # (faces x corners, 3)
        assert np.allclose(np.unique(V.round(9), axis=0), np.unique(q[l].round(9), axis=0))
    assert f"L = {e.L}" in ax.get_title()
    assert save_figure(ax, tmp_path, "fig6_tube")[0].stat().st_size > 5000
    plt.close(ax.figure)


def test_fig9_shows_every_tube_set_of_the_plan_obstacles_and_a_few_runs(voxels, tmp_path):
    ts, plan, res = voxels
    d = ts.decomposition
    ax = plot_plan_tubes_3d(ts, plan, res, runs=RunsStyle(max_runs=4))
    assert len(solids(ax, "tube")) == plan.cost == sum(ts.edges[k].L for k in plan.edges)
    assert len(solids(ax, "start")) == 1 and len(solids(ax, "target")) == 1
    assert 1 <= len(solids(ax, "obstacle")) <= len(d.obstacles)
    assert len(ax.lines) == 4 and "4 of 30 runs drawn" in ax.get_title()
    runs = np.asarray(res.trajectories)
    drawn = [[j for j in range(30) if np.allclose(np.stack(ln.get_data_3d(), axis=1), runs[j])] for ln in ax.lines]
    assert all(len(j) == 1 for j in drawn) and len({j[0] for j in drawn}) == 4   # 4 different runs, in 3-D
    png, pdf = save_figure(ax, tmp_path, "fig9_tubes3d")
    assert png.stat().st_size > 5000 and pdf.read_bytes()[:5] == b"%PDF-"
    plt.close(ax.figure)


# ------------------------------------------------------------------ the app
def test_simulate_app_writes_layer_and_3d_figures_for_a_voxel_map(voxels, tmp_path):
    sys.path.insert(0, str(ROOT / "experiments"))
    from simulate import write_figures, write_spec_figure

    ts, plan, res = voxels
    plt.close("all")                                  # what earlier tests left open is not the app's
    files = write_figures(ts, plan, res, tmp_path)
    stems = sorted({Path(f).stem for f in files})
    assert stems == ["fig5_workspace", "fig6_tube", "fig7_trajectories", "fig9_tubes3d", "transition_graph"]
    assert len(files) == 10 and all(Path(f).stat().st_size > 1000 for f in files)
    sp = plan_formula(ts, ts.decomposition.cells_with_label("1")[0], "F(l2)")
    sim = simulate_spec(ts, sp, SimulationRuns(n_runs=5, mode="uniform", seed=0))
    files = write_spec_figure(ts, sp, sim, tmp_path)
    assert sorted(Path(f).name for f in files) == ["fig8_specification.pdf", "fig8_specification.png"]
    assert not plt.get_fignums()                                              # every figure closed
