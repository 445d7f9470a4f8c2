"""Labelled regions given as boxes on a box grid: covered when avoided, contained when visited.

The map is ``[0, 3]^2`` cut into 3 x 3 unit cells (cell ``(i, j)`` is ``[i, i+1] x [j, j+1]``).
Region 1 is the box ``[0, 1.4] x [2, 3]``: the whole cell ``(0, 2)`` and 40 % of cell ``(1, 2)``.
Rounding by cell centre (the old rule) left that 40 % unlabelled, so ``G !l1`` let tubes into it.
"""

import dataclasses

import numpy as np
import pytest
import shapely

from tubejax.analyses.control.planner import PlanningError
from tubejax.errors import InputError
from tubejax.analyses.spec import cell_letters, edge_letters, map_alphabet, plan_formula, plan_patrol, simulate_spec
from tubejax.analyses.spec.labelling import MEET_TOL
from tubejax.analyses.spec.monitor import region_letters
from tubejax.analyses.spec.regions import region_pieces
from tubejax.model.workspace import box_grid
from tubejax.model.workspace.boxgrid import LABEL_REGIONS, BoxGridError
from tubejax.analyses.control import SimulationRuns

BOX1 = ([0, 2], [1.4, 3])
LABELS = {"1": BOX1, "2": ([2, 2], [3, 3]), "3": ([0, 0], [1, 1])}
REGION1 = shapely.box(0, 2, 1.4, 3)


def grid():
    return box_grid([0, 0], [3, 3], [3, 3], labels=LABELS)


def cell(d, i, j):
    return int(np.flatnonzero((d.grid == [i, j]).all(axis=1))[0])


@pytest.fixture(scope="module")
def box_ts():
    from tubejax.abstraction import build_abstraction
    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set
    return build_abstraction(grid(), LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1)),
                             L_max=6, progress=False)


def tube_sets(ts, k):
    e = ts.edges[k]
    Z = ts.z_of(e.src, e.dst).vertices
    return [shapely.MultiPoint(ts.tubes[k].p[l] + ts.tubes[k].eps[l] * Z).convex_hull for l in range(e.L)]


def test_only_cells_inside_the_box_carry_the_label_and_the_box_is_kept():
    d = grid()
    assert d.labels[cell(d, 0, 2)] == "1" and d.labels[cell(d, 1, 2)] is None     # 40 % inside: no visit
    assert d.labels[cell(d, 2, 2)] == "2" and d.labels[cell(d, 0, 0)] == "3"
    (P,) = d._cache[LABEL_REGIONS]["1"]
    assert np.allclose(P.bounding_box(), BOX1)
    assert [b for b, _ in region_pieces(d, ["1"])] == [0]
    # the cut cell may be in region 1 but is not surely; its neighbour below touches the box's lower edge
    assert cell_letters(d, ["1"], cell(d, 1, 2)) == (0, 1)
    assert cell_letters(d, ["1"], cell(d, 0, 2)) == (1, 1)
    assert cell_letters(d, ["1"], cell(d, 1, 1)) == (0, 1)
    assert cell_letters(d, ["1"], cell(d, 2, 2)) == (0, 0)
    assert map_alphabet(d, ["1", "2"]).tolist() == [True, True, True, False]     # 1 and 2 never meet


def test_points_in_the_cut_part_read_the_label():
    d = grid()
    X = np.array([[1.2, 2.5], [1.4, 2.0], [1.5, 2.5], [0.5, 2.5], [1.2, 1.99]])
    assert region_letters(d, ["1"], X).tolist() == [1, 1, 0, 1, 0]


def test_boxes_that_cannot_be_visited_or_share_a_cell_are_refused():
    with pytest.raises(BoxGridError, match=r"labels\['a'\]: the box \[0.2, 0.2\]..\[1.8, 1.8\] contains no "
                                           r"whole free cell.*grid lines axis 0: 0, 1, 2, 3"):
        box_grid([0, 0], [3, 3], [3, 3], labels={"a": ([0.2, 0.2], [1.8, 1.8])})
    with pytest.raises(BoxGridError, match=r"labels\['b'\]: cell \[0, 0\] is already labelled 'a' \(it lies inside both boxes"):
        box_grid([0, 0], [3, 3], [3, 3], labels={"a": ([0, 0], [1, 1]), "b": ([0, 0], [2, 1])})
    assert issubclass(BoxGridError, InputError)
    # grid lines that differ from the box's corners by rounding only still count as inside
    d = box_grid([0, 0], [0.3, 0.3], [3, 3], labels={"a": ([0.1, 0.1], [0.2, 0.2])})
    assert d.labels.count("a") == 1


def test_tube_letters_use_the_box_exactly(box_ts):
    """may = the tube set meets the closed box (sets within MEET_TOL count), must = it lies inside
    it: checked against shapely for every tube set; some sets meet only the cut 40 %, which cells
    alone would miss."""
    ts = box_ts
    lt = edge_letters(ts, ["1"])
    only_cut = 0
    for k in range(ts.n_edges):
        for l, Q in enumerate(tube_sets(ts, k)):
            may = bool(lt.may[k, l] & 1)
            if Q.intersects(REGION1):
                assert may, (k, l)
            elif may:                    # closer than MEET_TOL along an axis (both sets are boxes) counts
                assert Q.distance(REGION1) <= np.sqrt(2) * MEET_TOL, (k, l)
            assert bool(lt.must[k, l] & 1) == REGION1.buffer(1e-9).contains(Q), (k, l)
            only_cut += Q.intersects(REGION1) and not Q.intersects(shapely.box(0, 2, 1, 3))
    assert only_cut > 0


def test_avoided_box_is_never_crossed(box_ts):
    """From cell (2, 2): visit 3, then 2, never region 1. Without the box (cells only, the old
    rounding) the plan goes 8 -> 0 -> 8 with a tube through the cut 40 %; with it, it goes round."""
    ts = box_ts
    d = ts.decomposition
    start, f = cell(d, 2, 2), "G !l1 & F(l3 & F l2)"
    sp = plan_formula(ts, start, f)
    assert not any(Q.intersects(REGION1) for k in sp.plan.edges for Q in tube_sets(ts, k))
    old = dataclasses.replace(ts, decomposition=dataclasses.replace(d, _cache={}))
    sp_old = plan_formula(old, start, f)
    assert sp_old.cost < sp.cost
    assert any(Q.intersects(REGION1) for k in sp_old.plan.edges for Q in tube_sets(ts, k))
    s = simulate_spec(ts, sp, SimulationRuns(n_runs=200, mode="adversarial", seed=0)).summary()
    assert s["runs_satisfying_spec"] == 200 and s["avoided_region_entries"] == 0 and s["tube_exits"] == 0


def test_start_in_the_cut_cell(box_ts):
    d = box_ts.decomposition
    assert cell(d, 1, 2) == 5
    with pytest.raises(PlanningError, match=r"may already be violated at the start cell 5: .*the start cell meets "
                                            r"regions 1, 2"):
        plan_formula(box_ts, cell(d, 1, 2), "G !l1 & F l2")
    with pytest.raises(PlanningError, match=r"the start cell 5 meets the avoided region 1"):
        plan_patrol(box_ts, cell(d, 1, 2), ["2", "3"], avoid=["1"])
    sp = plan_patrol(box_ts, cell(d, 2, 0), ["2", "3"], avoid=["1"])
    assert not any(Q.intersects(REGION1) for k in sp.plan.edges for Q in tube_sets(box_ts, k))


def test_a_visit_needs_a_cell_inside_the_box(box_ts):
    """A box holding 60 % of cell (1, 2), its centre included, does not label that cell (the old
    rule did: a plan stopping there would count as a visit with the state possibly outside)."""
    d = box_grid([0, 0], [3, 3], [3, 3], labels={"1": ([0, 2], [1.6, 3])})
    assert d.labels[cell(d, 1, 2)] is None and d.labels[cell(d, 0, 2)] == "1"
    assert cell_letters(d, ["1"], cell(d, 1, 2)) == (0, 1)
    sp = plan_formula(box_ts, cell(box_ts.decomposition, 2, 0), "F l1")
    s = simulate_spec(box_ts, sp, SimulationRuns(n_runs=200, mode="adversarial", seed=1)).summary()
    assert s["runs_satisfying_spec"] == 200


def test_figure_shades_the_box_not_the_cells(box_ts):
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.collections import PolyCollection

    from tubejax.analyses.plot import plot_specification
    sp = plan_formula(box_ts, cell(box_ts.decomposition, 2, 2), "G !l1 & F l3")
    ax = plot_specification(box_ts, sp)
    shaded = [c for c in ax.collections if isinstance(c, PolyCollection) and c.get_label() == "avoided region"]
    (verts,) = [p.vertices for p in shaded[0].get_paths()]
    assert np.allclose(verts.min(0), [0, 2]) and np.allclose(verts.max(0), [1.4, 3])
