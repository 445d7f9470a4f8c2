"""The join of factor tables (tubejax.abstraction.product_join) against a brute-force recomputation.

The join enumerates only the pairs within reach (the product of the groups' reach lists) and tests
bounding boxes with a summed-volume table and, on lifted maps, pair hulls on the map. The oracle
here takes every ordered pair of cells, ANDs the factor masks straight from the tables, tests the
bounding box against every obstacle box by coordinate comparisons, and the pair hull with shapely
(position projection of a lifted 2-D map) or the n-D overlap test of the full decomposition. The
factor tables are random (any table is a valid input of the join), so many cases are hit.
Also: the vectorised lift builds the same cells as ``Polytope.box``.
"""

import numpy as np
import pytest
import shapely

from tubejax.abstraction import product_join
from tubejax.abstraction.product_join import join_factors
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.product_structure import product_structure
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.system_kinds import double_integrator_lookahead
from tubejax.model.workspace import box_grid, parse_grid_map
from tubejax.model.workspace.lookahead import lift_lookahead, position_view
from tubejax.model.workspace.voxelmap import parse_map
from tubejax.model.zshape.kinds import cross_sections

L_MAX = 5

VOXELS = "1..\n.#.\n...\n---\n..#\n#..\n..2\n"
GRID = "1...\n....\n#..#\n...2\n"


class _Table:
    """A factor table with random verdicts: ``feasible (2, L_max, F, F)``, ``margin`` alike."""

    def __init__(self, rng, F: int, density: float):
        self.L_max = L_MAX
        self.feasible = rng.random((2, L_MAX, F, F)) < density
        self.margin = np.where(self.feasible, rng.random((2, L_MAX, F, F)), np.nan)

    @property
    def mask(self) -> np.ndarray:
        bits = np.left_shift(np.uint64(1), np.arange(self.L_max, dtype=np.uint64))
        return np.bitwise_or.reduce(np.where(self.feasible, bits[None, :, None, None], np.uint64(0)), axis=1)


def _structure(decomp, d: int):
    A, B = double_integrator_lookahead(d, 0.5, 2.0)
    system = LinearSystem(A=A.astype(float), B=B.astype(float), U=box_input_set(1.0, d), W=Ball(2 * d, 0.01))
    return product_structure(decomp, system, cross_sections(decomp, "cell", 1.0))


def _hull_cases_2d(decomp, src, dst):
    """A lifted 2-D map: does the hull of the two map cells meet an obstacle's interior (shapely)?"""
    view = position_view(decomp)
    lo, hi = view.base.cell_boxes()
    union = shapely.union_all(list(view.base.obstacles))
    out = []
    for i, j in zip(view.base_cell[src], view.base_cell[dst]):
        hull = shapely.union(shapely.box(*lo[i], *hi[i]), shapely.box(*lo[j], *hi[j])).convex_hull
        out.append(bool(shapely.relate_pattern(hull, union, "2********")))
    return np.array(out, dtype=bool)


def brute_join(decomp, structure, tables, hull_cases):
    """Every ordered pair, straight from the tables; returns the edge rows and the joint-LP rows."""
    N, cf = decomp.n_cells, structure.cell_factor
    lo, hi = decomp.cell_boxes()
    o = [P.bounding_box() for P in decomp.obstacles]
    assert all(P.H.shape[0] == 2 * decomp.dim for P in decomp.obstacles)      # box obstacles only
    edges, maybe_joint, tested = [], [], 0
    for i in range(N):
        for j in range(N):
            box = src = ~np.uint64(0)
            for g, t in enumerate(tables):
                box &= t.mask[0][cf[i, g], cf[j, g]]
                src &= t.mask[1][cf[i, g], cf[j, g]]
            if i == j or box == 0:
                continue
            tested += 1
            b_lo, b_hi = np.minimum(lo[i], lo[j]), np.maximum(hi[i], hi[j])
            blocked = any(np.all(np.maximum(b_lo, a) < np.minimum(b_hi, b)) for a, b in o)
            mask = src if blocked else box
            if blocked:
                below = ~np.uint64(0) if src == 0 else (src & (~src + np.uint64(1))) - np.uint64(1)
                if box & below:
                    maybe_joint.append((i, j, int(box & below)))
            if mask:
                bit = next(L for L in range(L_MAX) if int(mask) >> L & 1)
                v = int(blocked)
                margin = min(t.margin[v, bit, cf[i, g], cf[j, g]] for g, t in enumerate(tables))
                edges.append((i, j, bit + 1, margin, v))
    s, d = (np.array([x[k] for x in maybe_joint], dtype=int) for k in (0, 1))
    hull = hull_cases(decomp, s, d) if maybe_joint else []
    return edges, [x for x, h in zip(maybe_joint, hull) if not h], tested


def _check(decomp, structure, tables, hull_cases, memory_mb):
    J = join_factors(decomp, structure, tables, memory_mb=memory_mb)
    edges, joint, tested = brute_join(decomp, structure, tables, hull_cases)
    assert len(edges) > 0 and J.n_box_tested == tested
    got = list(zip(J.src.tolist(), J.dst.tolist(), J.L.tolist(), J.margin.tolist(), J.variant.tolist()))
    assert got == edges                                                       # same rows, same order
    assert list(zip(J.joint_src.tolist(), J.joint_dst.tolist(), J.joint_box_mask.tolist())) == joint
    return J, edges, joint


@pytest.fixture(scope="module")
def lifted_voxels():
    d = lift_lookahead(parse_map(VOXELS), [2, 2, 1])
    return d, _structure(d, 3)


@pytest.fixture(scope="module")
def lifted_grid():
    d = lift_lookahead(parse_grid_map(GRID), [3, 2])
    return d, _structure(d, 2)


@pytest.mark.parametrize("seed,density,memory_mb", [(0, 0.5, 256.0), (1, 0.2, 1e-9), (2, 0.8, 0.01)])
def test_join_of_a_lifted_voxel_map_equals_the_brute_force(lifted_voxels, seed, density, memory_mb):
    d, st = lifted_voxels
    rng = np.random.default_rng(seed)
    tables = [_Table(rng, f.n_cells, density) for f in st.factors]
    J, edges, joint = _check(d, st, tables, lambda dd, s, t: dd.obstacle_cases(s, t), memory_mb)
    assert set(J.variant.tolist()) == {0, 1}
    assert len(J.src) < d.n_cells * (d.n_cells - 1)                          # reach lists: not all pairs


@pytest.mark.parametrize("seed", [3, 4])
def test_join_of_a_lifted_grid_map_equals_the_brute_force_with_shapely_hulls(lifted_grid, seed):
    d, st = lifted_grid
    rng = np.random.default_rng(seed)
    tables = [_Table(rng, f.n_cells, 0.6) for f in st.factors]
    J, edges, joint = _check(d, st, tables, _hull_cases_2d, 0.05)
    assert len(joint) > 0                                                     # blocked boxes with free hulls


@pytest.mark.parametrize("grid_table", [True, False])
def test_join_of_a_4d_box_grid_equals_the_brute_force(monkeypatch, grid_table):
    d = box_grid([0, 0, 0, 0], [4, 4, 3, 3], [4, 4, 3, 3],
                 obstacles=[([1, 1, 0, 0], [2, 2, 3, 3]), ([2, 0, 1, 1], [3, 1, 2, 2])])
    st = _structure(d, 2)
    if not grid_table:                                                        # the coordinate comparisons
        monkeypatch.setattr(product_join, "GRID_TABLE_MAX", 0)
    d._cache.pop("product_box_obstacles", None)
    rng = np.random.default_rng(5)
    tables = [_Table(rng, f.n_cells, 0.5) for f in st.factors]
    J, edges, joint = _check(d, st, tables, lambda dd, s, t: dd.obstacle_cases(s, t), 1.0)
    index = d._cache.pop("product_box_obstacles")
    assert isinstance(index, product_join._GridObstacles) == grid_table
    assert set(J.variant.tolist()) == {0, 1}


def test_two_cells_with_the_same_factor_cells_are_refused(lifted_grid):
    d, st = lifted_grid
    cf = st.cell_factor.copy()
    cf[1] = cf[0]
    with pytest.raises(ValueError, match="same factor cells"):
        product_join._Reach(cf, [t.mask for t in [_Table(np.random.default_rng(0), f.n_cells, 0.5)
                                                  for f in st.factors]])


@pytest.mark.parametrize("text,parse,div", [(VOXELS, parse_map, [2, 3, 2]), (GRID, parse_grid_map, [2, 3]),
                                            (GRID, parse_grid_map, 1)])
def test_the_lift_builds_the_cells_of_polytope_box(text, parse, div):
    d = lift_lookahead(parse(text), div)
    lo, hi = d.cell_boxes()
    for k, P in enumerate(d.cells):
        Q = Polytope.box(lo[k], hi[k])
        for a, b in ((P.vertices, Q.vertices), (P.H, Q.H), (P.h, Q.h)):
            np.testing.assert_array_equal(a, b)
    lo2 = np.array([P.bounding_box()[0] for P in d.cells])
    hi2 = np.array([P.bounding_box()[1] for P in d.cells])
    np.testing.assert_array_equal(lo, lo2)
    np.testing.assert_array_equal(hi, hi2)
