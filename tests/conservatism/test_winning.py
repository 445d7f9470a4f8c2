"""Every method's winning set lies inside the reach-avoid limit (docs/math/limit.md#winning-sets).

The winning cells come from the transition systems (HiGHS, small maps), the limit from the
polygon fixed point: two independent computations of one fact (a cell with a path of
verified edges to the target is won by some feedback, so it lies in ``R_∞``). A cell partly
outside the limit is a bug in one of them, and the failure names it.
"""

import functools
from pathlib import Path

import networkx as nx
import numpy as np
import pytest
import shapely

import tubejax as tj
from tubejax.analyses.conservatism import cells_outside, reach_avoid_limit, winning_set
from tubejax.model.geometry import Ball

AVOID_MAP = "1.4.2\n.###.\n3....\n"
CORRIDOR = "1..#...\n.#.#.#.\n.#...#2\n...#...\n"
#: (map, target, avoid, A): the paper's point mass, and two systems whose limit is smaller than S.
CASES = {
    "avoid": (AVOID_MAP, "2", ("4",), np.eye(2)),
    "shear": (CORRIDOR, "2", (), np.array([[1.0, 0.3], [0.0, 1.0]])),
    "saddle": (CORRIDOR, "2", (), np.array([[1.1, 0.0], [0.0, 0.9]])),
}
METHODS = [("tube", "box"), ("tube", "diamond"), ("tube", "cell"), ("openloop", "box"), ("exact2d", "box")]


def _system(A, r):
    return tj.LinearSystem(A=A, B=0.5 * np.eye(2), U=tj.box_input_set(1.0, 2), W=Ball(2, r))


@functools.lru_cache(maxsize=None)
def _limit(case, r):
    text, target, avoid, A = CASES[case]
    ws = tj.grid_map(text)
    return ws, reach_avoid_limit(ws.decomposition, _system(A, r), target, avoid)


@functools.lru_cache(maxsize=None)
def _winning(case, r, method, z):
    text, target, avoid, A = CASES[case]
    ws, _ = _limit(case, r)
    ts = tj.abstract(ws, _system(A, r), method=method, solver=None if method == "exact2d" else "highs", zshape=z,
                     L_max=6)
    return ts, winning_set(ts, target, avoid)


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("r", [0.1, 0.3])
@pytest.mark.parametrize("method,z", METHODS)
def test_every_winning_cell_lies_in_the_limit(case, r, method, z):
    ws, lim = _limit(case, r)
    assert lim.converged
    _, win = _winning(case, r, method, z)
    bad = cells_outside(win, lim.geometry, ws.decomposition)
    assert not bad, (f"{case}, r = {r}, {method} (Z {z}): winning cells partly outside the limit "
                     + ", ".join(f"cell {c} ({a:.3g} of its area)" for c, a in bad))
    assert win.area <= lim.area * (1 + 1e-9)


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("r", [0.1, 0.3])
def test_the_exact_cell_abstraction_wins_every_cell_the_others_win(case, r):
    exact = set(_winning(case, r, "exact2d", "box")[1].cells)
    for method, z in METHODS:
        cells = set(_winning(case, r, method, z)[1].cells)
        assert cells <= exact, f"{method} (Z {z}) wins cells {sorted(cells - exact)} that exact2d does not"


def test_winning_cells_are_the_ancestors_of_the_target_cells():
    ts, win = _winning("shear", 0.1, "tube", "box")
    G = nx.DiGraph([(e.src, e.dst) for e in ts.edges])
    goals = ts.decomposition.cells_with_label("2")
    expect = set(goals).union(*(nx.ancestors(G, g) for g in goals if g in G))
    assert set(win.cells) == expect
    assert win.summary(win.area * 2) == {"winning_area": win.area, "winning_cells": sorted(expect),
                                         "fraction_of_limit": 0.5}


def test_an_avoided_region_blocks_the_only_way():
    ws = tj.grid_map("1.4.6\n")                          # cells 0..4; region 4 (cell 2) walls off 6
    sys_ = _system(np.eye(2), 0.2)
    lim = reach_avoid_limit(ws.decomposition, sys_, "6", ["4"])
    assert lim.converged and lim.area == pytest.approx(2.0, abs=1e-6)
    for method in ("tube", "exact2d"):
        ts = tj.abstract(ws, sys_, method=method, solver=None if method == "exact2d" else "highs", L_max=4)
        assert winning_set(ts, "6", ["4"]).cells == (3, 4)
        assert winning_set(ts, "6").cells == (0, 1, 2, 3, 4)
    assert float(shapely.intersection(lim.geometry, shapely.box(0, 0, 3, 1)).area) < 1e-9


def test_bad_labels_are_refused():
    ts, _ = _winning("avoid", 0.1, "tube", "box")
    with pytest.raises(ValueError, match="target: no cell carries the label '9'"):
        winning_set(ts, "9")
    with pytest.raises(ValueError, match="avoid: the target '2' is also avoided"):
        winning_set(ts, "2", ["2"])


def test_a_polygon_workspace_too():
    ws = tj.polygon_workspace(str(Path(__file__).resolve().parents[2] / "conf" / "workspace" / "maps" / "rooms.yaml"))
    sys_ = _system(np.array([[1.0, 0.3], [0.0, 1.0]]), 0.1)
    lim = reach_avoid_limit(ws.decomposition, sys_, "2")
    assert lim.converged and 0 < lim.area < lim.free_area
    ts = tj.abstract(ws, sys_, method="exact2d", zshape="cell", L_max=3)
    win = winning_set(ts, "2")
    assert len(win.cells) > len(ws.decomposition.cells_with_label("2"))
    assert not cells_outside(win, lim.geometry, ws.decomposition)
