"""Decompositions are validated when built (issue 11, finding 6), and where W fits (finding 5)."""

import itertools

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from tubejax.errors import DecompositionError, InputError
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.workspace import CellDecomposition, box_grid, parse_grid_map
from tubejax.model.workspace.validate import box_overlap_pairs, disturbance_fits, validate_decomposition

SQ = Polytope.box([0, 0], [1, 1])


def decomposition(cells, obstacles=(), labels=None, grid=None):
    return CellDecomposition(tuple(cells), tuple(labels or [None] * len(cells)), tuple(obstacles),
                             None if grid is None else np.array(grid), "hand-built")


def flat_polytope(V):
    """A hand-built zero-area 'polytope' (what from_convex_polygon used to build from collinear points)."""
    V = np.asarray(V, float)
    H = np.array([[0.0, -1.0], [0.0, 1.0], [-1.0, 0.0], [1.0, 0.0]])
    return Polytope(V, H, np.array([-V[:, 1].min(), V[:, 1].max(), -V[:, 0].min(), V[:, 0].max()]))


def test_valid_decompositions_pass():
    decomposition([SQ, Polytope.box([1, 0], [2, 1])], obstacles=[shapely.box(0, 1, 2, 2)])   # touching is fine
    decomposition([Polytope.from_vertices([[0, 0], [1, 0], [0, 1]]), Polytope.from_vertices([[1, 0], [1, 1], [0, 1]])])
    box_grid([0, 0, 0], [1, 1, 1], 3, obstacles=[([0, 0, 0], [1 / 3, 1, 1])])


def test_free_cell_coinciding_with_an_obstacle_is_refused():
    """The issue's case: a free cell equal to an obstacle got certified edges and passed verify()."""
    for obstacle in (shapely.box(1, 0, 2, 1), Polytope.box([1, 0], [2, 1])):
        with pytest.raises(DecompositionError, match=r"cell 1 \(label 'A', grid \[0, 1\]\) meets the interior "
                                                     r"of obstacle 0 \(common area 1"):
            decomposition([SQ, Polytope.box([1, 0], [2, 1])], obstacles=[obstacle], labels=[None, "A"],
                          grid=[[0, 0], [0, 1]])
    with pytest.raises(DecompositionError, match="cell 0 meets the interior of obstacle 0"):   # 3-D, LP-free path
        decomposition([Polytope.box([0, 0, 0], [1, 1, 1])], obstacles=[Polytope.box([0.5, 0, 0], [2, 1, 1])])


def test_zero_volume_cell_is_refused():
    with pytest.raises(DecompositionError, match=r"cell 1 has no volume"):
        decomposition([SQ, flat_polytope([[1, 0], [2, 0], [3, 0], [2, 0]])])


def test_overlapping_cells_are_refused_2d_and_nd():
    with pytest.raises(DecompositionError, match=r"cell 0 \(label '1'\) and cell 1 overlap \(common area 0.5"):
        decomposition([SQ, Polytope.box([0.5, 0], [1.5, 1])], labels=["1", None])
    tri = Polytope.from_vertices([[0, 0], [1, 0], [0, 1]])
    with pytest.raises(DecompositionError, match="cell 0 and cell 1 overlap"):                 # non-box: exact shapely
        decomposition([tri, Polytope.from_vertices([[0.2, 0.2], [1, 0.2], [0.2, 1]])])
    with pytest.raises(DecompositionError, match="cell 0 and cell 2 overlap"):                 # a duplicated cell
        decomposition([SQ, Polytope.box([1, 0], [2, 1]), SQ])
    with pytest.raises(DecompositionError, match=r"cell 1 and cell 2 overlap \(depth 0.25"):   # 3-D boxes
        decomposition([Polytope.box([5, 5, 5], [6, 6, 6]), Polytope.box([0, 0, 0], [1, 1, 1]),
                       Polytope.box([0.5, 0.5, 0.5], [1.5, 1.5, 1.5])])
    simplex = Polytope.from_vertices(np.vstack([np.zeros(3), np.eye(3)]))
    with pytest.raises(DecompositionError, match="cell 0 and cell 1 overlap"):                 # 3-D, one LP
        decomposition([simplex, Polytope.box([0.1, 0.1, 0.1], [1, 1, 1])])


def test_inconsistent_and_non_simple_cells_are_refused():
    bad = Polytope(SQ.vertices, SQ.H, SQ.h - 0.5)                    # facets do not match the vertices
    with pytest.raises(DecompositionError, match="vertices violate its own facets"):
        decomposition([bad])
    R = Polytope.box([0, 0], [2, 1])
    bowtie = Polytope(np.array([[0.0, 0], [2, 0], [0, 1], [1, 1]]), R.H, R.h)      # edges cross, area 0.5
    with pytest.raises(DecompositionError, match=r"cell 0 is not a simple polygon \(Self-intersection"):
        decomposition([bowtie])
    with pytest.raises(DecompositionError, match="obstacle 0 is not a valid polygon"):
        decomposition([SQ], obstacles=[shapely.Polygon([(3, 3), (4, 4), (4, 3), (3, 4)])])
    nan = Polytope(SQ.vertices * np.nan, SQ.H, SQ.h)
    with pytest.raises(DecompositionError, match="cell 0 holds NaN"):
        decomposition([nan])


def test_errors_are_input_errors():
    assert issubclass(DecompositionError, InputError) and issubclass(DecompositionError, ValueError)


def brute_pairs(lo, hi, tol):
    return sorted((i, j) for i, j in itertools.combinations(range(len(lo)), 2)
                  if np.all(np.minimum(hi[i], hi[j]) - np.maximum(lo[i], lo[j]) > tol))


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.integers(1, 4), st.integers(0, 40), st.integers(0, 2 ** 31 - 1), st.booleans())
def test_box_overlap_pairs_equals_brute_force(n, N, seed, huge):
    rng = np.random.default_rng(seed)
    lo = np.round(rng.uniform(0, 4, (N, n)), 1)                     # rounded: many exact touches
    hi = lo + np.round(rng.uniform(0.1, 1.5, (N, n)), 1)
    if huge and N:
        hi[0] = lo[0] + 50                                          # one huge box coarsens the hash grid
    got = [tuple(p) for p in box_overlap_pairs(lo, hi, 1e-9).tolist()]
    assert got == brute_pairs(lo, hi, 1e-9)


def test_grid_map_validation_scales():
    """A 10,000-cell map validates (its cost is measured in a benchmark, not here): every pair is checked."""
    d = parse_grid_map("\n".join(["." * 100] * 100))
    assert d.n_cells == 10_000
    validate_decomposition(d)                                        # no error: the grid is a decomposition


def test_disturbance_fits_boxes_closed_form():
    d = parse_grid_map("..\n..\n")                                   # unit squares
    assert disturbance_fits(d, Ball(2, 0.5)).all()                   # P - W is the single centre point
    assert not disturbance_fits(d, Ball(2, 0.5 + 1e-6)).any()
    assert disturbance_fits(d, Polytope.box([-0.5, -0.2], [0.5, 0.2])).all()
    assert not disturbance_fits(d, Polytope.box([-0.3, -0.1], [0.8, 0.1])).any()      # width 1.1 > 1


def test_disturbance_fits_triangles_match_the_inradius():
    """For triangles and a ball, P - W is non-empty iff r <= inradius = 2 area / perimeter."""
    rng = np.random.default_rng(1)
    cells, inradii = [], []
    for k in range(6):
        V = rng.uniform(0, 1, (3, 2)) + [2 * k, 0]
        P = Polytope.from_vertices(V)
        cells.append(P)
        poly = shapely.Polygon(P.vertices)
        inradii.append(2 * poly.area / poly.length)
    d = decomposition(cells)
    for r in np.linspace(0.01, 0.2, 7):
        assert disturbance_fits(d, Ball(2, r)).tolist() == [r <= rho + 1e-7 for rho in inradii]
    poly_W = Polytope.from_vertices([[0.05, 0], [0, 0.05], [-0.05, -0.05]])
    expect = []
    for P in cells:                                                  # P - W = intersection of P - w over W's vertices
        inner = shapely.Polygon(P.vertices)
        for w in poly_W.vertices:
            inner = inner.intersection(shapely.affinity.translate(shapely.Polygon(P.vertices), -w[0], -w[1]))
        expect.append(not inner.is_empty)
    assert disturbance_fits(d, poly_W).tolist() == expect


@pytest.mark.parametrize("block", [1, 7, 1 << 21])
def test_checks_in_blocks_give_the_same_errors_and_fits(monkeypatch, block):
    """The cell checks stack the cells in blocks of ``_BLOCK_NUMBERS`` coordinates (one cell per block
    down to one block for all): the same cell is named and ``disturbance_fits`` is the same as the
    closed form per cell, whatever the block size."""
    import tubejax.model.workspace.validate as validate
    monkeypatch.setattr(validate, "_BLOCK_NUMBERS", block)
    grid = box_grid([0, 0, 0], [3, 2, 2], [3, 2, 2])
    cells = list(grid.cells)
    fits = disturbance_fits(grid, Polytope.box([-0.45, -0.5, -0.5], [0.5, 0.5, 0.5]))
    assert fits.tolist() == [True] * len(cells)
    assert not disturbance_fits(grid, Polytope.box([-0.5, -0.5, -0.5], [0.55, 0.5, 0.5])).any()
    for bad_ids in ([5, 9], [0, 11], [10, 3]):
        broken = list(cells)
        for i in bad_ids:
            broken[i] = Polytope(cells[i].vertices * np.nan, cells[i].H, cells[i].h)
        with pytest.raises(DecompositionError, match=rf"cell {min(bad_ids)} holds NaN"):
            decomposition(broken)
        broken = list(cells)
        for i in bad_ids:
            broken[i] = Polytope(cells[i].vertices, cells[i].H, cells[i].h - 0.25)
        with pytest.raises(DecompositionError, match=rf"cell {min(bad_ids)}: its vertices violate its own facets"):
            decomposition(broken)
    validate_decomposition(grid)
