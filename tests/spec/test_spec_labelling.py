"""Which regions a tube set can meet: the vectorised test against shapely and against an LP."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.optimize import linprog

from tubejax.model.geometry import Polytope
from tubejax.model.geometry.obstacles import to_shapely
from tubejax.analyses.spec import cell_letters, edge_letters
from tubejax.analyses.spec.labelling import MEET_TOL, minkowski_normals


def check_against_shapely(ts, labels):
    """may: every Q_l that shapely says intersects a cell of the label has the bit (soundness),
    and any extra bit is within MEET_TOL; must: only when the cell covers Q_l (up to 1e-8)."""
    d = ts.decomposition
    lt = edge_letters(ts, labels)
    cells = {b: [to_shapely(d.cells[c]) for c in d.cells_with_label(l)] for b, l in enumerate(labels)}
    n_meets = 0
    for k, e in enumerate(ts.edges):
        q = ts.tubes[k].vertices(ts.Z[e.src], d.cells[e.src])
        for l in range(1, e.L + 1):
            Q = to_shapely(Polytope.from_vertices(q[l]))
            for b, polys in cells.items():
                may, must = bool(lt.may[k, l - 1] >> b & 1), bool(lt.must[k, l - 1] >> b & 1)
                hits = any(P.intersects(Q) for P in polys)
                n_meets += hits
                assert may or not hits, (e, l, labels[b])
                if may and not hits:
                    assert min(P.distance(Q) for P in polys) <= MEET_TOL
                if must:
                    assert any(P.buffer(1e-8).covers(Q) for P in polys)
                elif any(P.covers(Q) for P in polys):
                    assert l < e.L                  # the end cell's label is always must
        assert not lt.may[k, e.L:].any()
    return n_meets


def test_avoid_map_against_shapely(avoid_ts):
    assert check_against_shapely(avoid_ts, ["1", "2", "3", "4"]) > 0


def test_paper_map_against_shapely(paper_ts):
    assert check_against_shapely(paper_ts, ["1", "2", "3", "4", "5", "6"]) > 0


def test_tube_crossing_region_4(avoid_ts):
    """Edge (0,1) -> (0,4) runs along the top row through region 4's cell (0,2): some of its sets
    may meet it, two lie inside it."""
    d = avoid_ts.decomposition
    k = avoid_ts.edge_index()[1, 4]
    lt = edge_letters(avoid_ts, ["4"], [k])
    assert d.labels[1] is None and d.labels[4] == "2" and d.labels[2] == "4"
    L = avoid_ts.edges[k].L
    assert lt.may[0, :L - 1].sum() >= 3 and lt.must[0, :L - 1].any() and not lt.may[0, L - 1]
    assert ((lt.must[0] & ~lt.may[0]) == 0).all()


def test_tube_sweeping_region_5_without_entering_for_sure(paper_ts):
    """Paper map, edge (7,9) -> (8,8): Q_1..Q_3 touch region 5's cell (8,9), none lies inside it."""
    d = paper_ts.decomposition
    k = paper_ts.edge_index()[52, 56]
    assert tuple(d.grid[52]) == (7, 9) and tuple(d.grid[56]) == (8, 8)
    lt = edge_letters(paper_ts, ["5"], [k])
    assert lt.may[0].any() and not lt.must[0].any()


def test_end_cell_label_is_certain(avoid_ts):
    d = avoid_ts.decomposition
    into2 = [k for k, e in enumerate(avoid_ts.edges) if d.labels[e.dst] == "2"]
    lt = edge_letters(avoid_ts, ["2"], into2)
    assert all(lt.must[r, avoid_ts.edges[k].L - 1] == 1 for r, k in enumerate(into2))


def test_start_cell_letters(avoid_ts):
    d = avoid_ts.decomposition
    assert cell_letters(d, ["1", "4"], 0) == (1, 1)                 # cell 0 (label 1) touches no 4
    assert cell_letters(d, ["1", "4"], 1) == (0, 3)                 # cell (0,1) touches 1 and 4
    assert cell_letters(d, ["2"], 6) == (0, 1)                      # (1,4) shares a side with (0,4)
    assert cell_letters(d, ["2"], 10) == (0, 0)                     # (2,3) is a row away from it
    assert tuple(d.grid[6]) == (1, 4) and tuple(d.grid[10]) == (2, 3)


def test_other_methods_are_refused(avoid_ts):
    import dataclasses
    with pytest.raises(ValueError, match="method 'tube'"):
        edge_letters(dataclasses.replace(avoid_ts, method="exact2d"), ["4"])


def random_polytope(draw, n):
    pts = np.array(draw(st.lists(st.lists(st.floats(-1, 1), min_size=n, max_size=n),
                                 min_size=n + 3, max_size=n + 6)))
    try:
        P = Polytope.from_vertices(pts)
    except Exception:
        return None
    if P.n_vertices < n + 1:
        return None
    return P


def _overlap_margin(Z, P, p, eps) -> float:
    """The LP oracle: max t s.t. H_Q x + t <= h_Q, H_P x + t <= h_P, Q = p + eps Z.

    HiGHS runs with feasibility tolerances of 1e-10: at its default 1e-7 a point ``Q`` (``eps = 0``)
    admits a spurious ``t`` of a few 1e-9 against the test's 1e-9 threshold."""
    n = len(p)
    HQ, hQ = Z.H, Z.H @ p + eps * Z.h
    A = np.vstack([np.hstack([HQ, np.ones((len(HQ), 1))]), np.hstack([P.H, np.ones((len(P.H), 1))])])
    res = linprog(np.r_[np.zeros(n), -1.0], A_ub=A, b_ub=np.r_[hQ, P.h],
                  bounds=[(None, None)] * n + [(None, 10.0)], method="highs",
                  options={"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10})
    assert res.status == 0
    return -res.fun


def test_oracle_sees_no_overlap_of_a_point_and_a_sliver():
    """Hypothesis's counterexample: Q = {(0, 0, -1)} (eps = 0) and a sliver P of width 1e-9 are
    apart (distance 1); the meet test says so, and so must the oracle."""
    Z = Polytope.from_vertices(np.array([[0, 0, 0.], [0, 0, 1], [0, 1, 0], [1, 0, 0]]))
    P = Polytope.from_vertices(np.array([[0, 0, 0.], [0, 0, 1], [0, 1, 0], [1e-9, 0.5, 1]]))
    p = np.array([0, 0, -1.])
    N = minkowski_normals(Z.vertices, P.vertices)
    gap = np.min(N @ p + np.max(-N @ P.vertices.T, axis=1))
    assert gap < 0
    assert _overlap_margin(Z, P, p, 0.0) <= 1e-9


@settings(max_examples=60, deadline=None)
@given(st.data(), st.sampled_from([2, 3]))
def test_meet_test_agrees_with_an_lp(data, n):
    """Q = p + eps Z meets P iff the LP max t s.t. H_Q x + t <= h_Q, H_P x + t <= h_P has t* >= 0."""
    Z, P = random_polytope(data.draw, n), random_polytope(data.draw, n)
    if Z is None or P is None:
        return
    p = np.array(data.draw(st.lists(st.floats(-2.5, 2.5), min_size=n, max_size=n)))
    eps = data.draw(st.floats(0.0, 1.5))
    N = minkowski_normals(Z.vertices, P.vertices)
    gap = np.min(N @ p + eps * np.max(N @ Z.vertices.T, axis=1) + np.max(-N @ P.vertices.T, axis=1))
    t = _overlap_margin(Z, P, p, eps)
    if t > 1e-9:                                  # interiors overlap
        assert gap >= -MEET_TOL
    if t < -1e-6:                                 # clearly apart
        assert gap < 0
    if gap > 1e-7:
        assert t >= -1e-9
    if gap < -1e-6:
        assert t < 1e-9


def test_map_alphabet_holds_every_letter_a_point_can_read():
    """Every point (cell corners, edge midpoints, random points) reads a letter of the alphabet."""
    from tubejax.analyses.spec import map_alphabet, region_letters
    from tubejax.model.workspace.gridmap import parse_grid_map
    rng = np.random.default_rng(0)
    for text, expect in [("12.\n3..\n", 8), ("1.2\n...\n3..\n", 4), ("1#2\n#..\n3.4\n", 5), ("1A\naA\n", 8),
                         ("1.2\n.2.\n...\n", 4)]:
        d = parse_grid_map(text)
        labels = sorted({l for l in d.labels if l is not None})
        ok = map_alphabet(d, labels)
        R, C = text.count("\n"), len(text.split("\n")[0])
        pts = [np.array([x, y]) for x in np.arange(0, C + 0.01, 0.5) for y in np.arange(0, R + 0.01, 0.5)]
        pts = np.vstack(pts + [rng.uniform([0, 0], [C, R], size=(500, 2))])
        assert ok[region_letters(d, labels, pts)].all(), text
        assert ok.sum() == expect, (text, np.flatnonzero(ok))


def test_dfa_over_the_map_alphabet_agrees_on_it():
    import itertools
    from tubejax.analyses.spec import dfa_from_formula, map_alphabet, parse_formula
    from tubejax.model.workspace.gridmap import parse_grid_map
    d = parse_grid_map("1.2\n...\n3.4\n")
    p = parse_formula("F(l1 & F(l2 & F(l3))) & G(!l4)", d.labels)
    ok = map_alphabet(d, p.labels)
    full, small = dfa_from_formula(p), dfa_from_formula(p, ok)
    assert small.n_states <= full.n_states and (small.alphabet == ok).all()
    letters = np.flatnonzero(ok)
    for n in range(1, 6):
        words = np.array(list(itertools.product(letters, repeat=n)))
        assert np.array_equal(full.accepts(words), small.accepts(words))
    bad = np.flatnonzero(~ok)[0]                      # a letter no point can read: rejecting sink
    assert not small.live()[small.delta[small.initial, bad]]
