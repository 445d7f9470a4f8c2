""""Surely in a region" for regions made of several cells: the maximal boxes of their union.

A tube set lying across two cells of one region lies in no single cell but surely in the region
(:func:`tubejax.analyses.spec.regions.cover_pieces`). Checked against shapely (the area of the set
minus the union of the region's cells), by brute force over small occupancy grids, and by planning
``FG a`` / ``G a`` on a grid map whose region ``a`` is 2 x 2 cells, whose adversarial runs' float64
region words Spot checks against the formula.
"""

import itertools

import numpy as np
import pytest
import shapely
from hypothesis import given, settings, strategies as st

import tubejax as tj
from tubejax.analyses.control import SimulationRuns, PlanningError
from tubejax.analyses.spec import lasso_words_satisfy, plan_ltl, simulate_spec
from tubejax.analyses.spec.monitor import region_letters
from tubejax.analyses.spec.regions import (_maximal_exact, _maximal_greedy, cover_pieces, inside_mask,
                                           maximal_boxes)
from tubejax.model.geometry import Polytope

#: Region a is the 2 x 2 block of cells in the top-left corner ([0, 2] x [1, 3]); b one cell.
SQUARE_MAP = "aa..\naa..\n...b\n"


def test_maximal_boxes_of_hand_drawn_unions():
    # an L of three unit squares: two maximal boxes, neither holds the corner triangle below
    L = maximal_boxes([[0, 0], [1, 0], [0, 1]], [[1, 1], [2, 1], [1, 2]])
    assert sorted((tuple(lo), tuple(hi)) for lo, hi in L) == [((0, 0), (1, 2)), ((0, 0), (2, 1))]
    assert [(tuple(lo), tuple(hi)) for lo, hi in maximal_boxes([[0, 0], [1, 0], [0, 1], [1, 1]],
                                                                [[1, 1], [2, 1], [1, 2], [2, 2]])] == [((0, 0), (2, 2))]
    # boxes that do not share grid lines: [0, 2] x [0, 1] and [1, 3] x [0, 1] merge into [0, 3] x [0, 1]
    assert [(tuple(lo), tuple(hi)) for lo, hi in maximal_boxes([[0, 0], [1, 0]], [[2, 1], [3, 1]])] == [((0, 0), (3, 1))]
    # two squares touching at a corner only: no box joins them
    assert len(maximal_boxes([[0, 0], [1, 1]], [[1, 1], [2, 2]])) == 2


def _brute_maximal(occ):
    n = occ.ndim
    ranges = [[(a, b) for a in range(d) for b in range(a, d)] for d in occ.shape]
    cov = {box for box in itertools.product(*ranges)
           if occ[tuple(slice(a, b + 1) for a, b in box)].all()}

    def inside(x, y):
        return all(ya <= xa and xb <= yb for (xa, xb), (ya, yb) in zip(x, y))
    return {x for x in cov if not any(y != x and inside(x, y) for y in cov)}, n


@pytest.mark.parametrize("seed", range(30))
def test_maximal_boxes_match_brute_force(seed):
    rng = np.random.default_rng(seed)
    shape = tuple(int(rng.integers(1, 5)) for _ in range(int(rng.integers(1, 4))))
    occ = rng.random(shape) < 0.7
    want, n = _brute_maximal(occ)
    assert set(_maximal_exact(occ)) == want
    greedy = set(_maximal_greedy(occ))                 # the fallback: maximal boxes covering every cell
    assert greedy <= want
    for cell in np.argwhere(occ):
        assert any(all(a <= i <= b for i, (a, b) in zip(cell, box)) for box in greedy)


def _region(mask_rows):
    text = "\n".join("".join("a" if c else "." for c in row) for row in mask_rows) + "\n"
    d = tj.grid_map(text).decomposition
    cells = [c for c, l in enumerate(d.labels) if l == "a"]
    return d, shapely.union_all([shapely.Polygon(d.cells[c].vertices) for c in cells])


quarter = st.integers(0, 16).map(lambda k: k / 4)          # exact binary fractions on [0, 4]


@settings(max_examples=150, deadline=None)
@given(rows=st.lists(st.lists(st.booleans(), min_size=4, max_size=4), min_size=4, max_size=4),
       xs=st.lists(quarter, min_size=2, max_size=2, unique=True),
       ys=st.lists(quarter, min_size=2, max_size=2, unique=True),
       pts=st.lists(st.tuples(quarter, quarter), min_size=3, max_size=7))
def test_surely_in_never_holds_for_a_set_that_pokes_out(rows, xs, ys, pts):
    """Boxes: surely in the region iff shapely finds no area outside it (sound and complete).
    Convex polygons: never surely in when some area lies outside (sound)."""
    if not any(map(any, rows)):
        rows[0][0] = True
    d, union = _region(rows)
    cover = cover_pieces(d, ["a"])
    Q = Polytope.box([min(xs), min(ys)], [max(xs), max(ys)])
    outside = shapely.box(min(xs), min(ys), max(xs), max(ys)).difference(union).area
    assert inside_mask(cover, Q) == (1 if outside == 0 else 0)
    hull = shapely.MultiPoint(pts).convex_hull
    if hull.area > 0:
        P = Polytope.from_vertices(np.array(hull.exterior.coords[:-1]))
        if hull.difference(union).area > 0:
            assert inside_mask(cover, P) == 0


@pytest.fixture(scope="module")
def square_ts():
    ws = tj.grid_map(SQUARE_MAP)
    return tj.abstract(ws, tj.paper_system(radius=0.2), solver="highs", L_max=10)


def _spot_check(ts, sp, seed):
    s = simulate_spec(ts, sp, SimulationRuns(n_runs=40, mode="adversarial", seed=seed))
    X = np.asarray(s.trajectories, np.float64)
    letters = region_letters(ts.decomposition, sp.dfa.labels, X)
    ok = lasso_words_satisfy(sp.spec, sp.dfa.propositions, letters, sp.stats["prefix_steps"],
                             sp.stats["cycle_steps"], sp.stats["cycles"])
    summary = s.summary()
    assert summary["obstacle_entries"] == 0 and summary["tube_exits"] == 0
    return ok


def test_reach_and_stay_in_a_region_of_four_grid_cells(square_ts):
    """FG la and G la: the cycle moves between cells of region a, its tubes across two of them."""
    ts = square_ts
    d = ts.decomposition
    a = [c for c, l in enumerate(d.labels) if l == "a"]
    far = next(c for c, l in enumerate(d.labels) if l == "b")
    sp = plan_ltl(ts, far, "FG la", cycles=3)
    cyc = sp.lasso["cycle"]
    assert set(cyc) <= set(a) and len(set(cyc)) >= 2          # it moves between cells of the region
    assert _spot_check(ts, sp, seed=1).all()
    sp2 = plan_ltl(ts, a[0], "G la", cycles=3)
    assert set(sp2.plan.cells) <= set(a)
    assert _spot_check(ts, sp2, seed=2).all()
    # the same runs fail a formula they do not meet: Spot's check is not vacuous
    s = simulate_spec(ts, sp2, SimulationRuns(n_runs=5, mode="adversarial", seed=3))
    letters = region_letters(d, sp2.dfa.labels, np.asarray(s.trajectories))
    assert not lasso_words_satisfy("FG !la", sp2.dfa.propositions, letters, sp2.stats["prefix_steps"],
                                   sp2.stats["cycle_steps"], 3).any()
    # staying in the one-cell region b is still unrealisable (no edge stays in one cell)
    with pytest.raises(PlanningError, match="region b has no self-sustaining cycle"):
        plan_ltl(ts, far, "FG lb")
