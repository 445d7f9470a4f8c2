"""The projection screen of the product path's joint LPs (tubejax.abstraction.joint_projections).

Checked against HiGHS on the joint LPs themselves: every pair horizon a projection refutes has an
infeasible joint LP (soundness), and the product system's joint edges are those the joint LPs give
without the screen, at the same least ``L`` (nothing lost).
"""

import numpy as np
import pytest

from tubejax.abstraction.joint_duals import DualReuseSolver
from tubejax.abstraction.joint_projections import ProjectionScreen, _ScreenSolver, product_polytope, projection_sets
from tubejax.abstraction.product_abstraction import JOINT, build_product_abstraction
from tubejax.abstraction.product_join import join_factors
from tubejax.lp.evidence.verdict import highs_solve_batch
from tubejax.model.geometry import Ball, Polytope, convex_hull_of
from tubejax.model.problem import Pairs, TubeProblem, pair_problems
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.system_kinds import double_integrator_lookahead
from tubejax.model.workspace import parse_grid_map
from tubejax.model.workspace.lookahead import lift_lookahead

L_MAX = 7


@pytest.fixture(scope="module")
def lifted():
    """A 4-D double integrator (two groups: position and look-ahead per axis) on a 4 x 4 map with one
    obstacle, lifted by 3 look-ahead slabs per axis: diagonal moves past the obstacle's corners have a
    blocked bounding box and a free hull, so they are joint LPs."""
    d = lift_lookahead(parse_grid_map("....\n.#..\n....\n....\n"), [3, 3])
    A, B = double_integrator_lookahead(2, 0.5, 2.0)
    sysm = LinearSystem(A=A.astype(float), B=B.astype(float), U=box_input_set(1.0, 2), W=Ball(4, 0.01))
    ps = build_product_abstraction(d, sysm, zshape="cell", L_max=L_MAX)
    joined = join_factors(d, ps.structure, ps.tables)
    assert len(joined.joint_src) > 0
    return d, sysm, ps, joined


@pytest.fixture(scope="module")
def highs_joint(lifted):
    """Every joint LP the join leaves (each pair at each ``L`` where its box LP is feasible) by HiGHS, and
    the screen's answer for it: ``{(i, j, L): (refuted, verdict)}``."""
    d, sysm, ps, joined = lifted
    screen = ProjectionScreen(ps.structure, sysm)
    out = {}
    for L in range(1, L_MAX + 1):
        k = np.flatnonzero((joined.joint_box_mask & (np.uint64(1) << np.uint64(L - 1))) != 0)
        s, t = joined.joint_src[k], joined.joint_dst[k]
        probs = pair_problems(d, sysm, ps.Z, Pairs(s, t, np.zeros(k.size, bool)), L)
        for i, j, h, v in zip(s.tolist(), t.tolist(), screen.refuted(s, t, L), highs_solve_batch(probs)):
            out[(i, j, L)] = (bool(h), v)
    return out


def test_projection_sets_are_the_pairs_of_groups():
    assert projection_sets(3) == [(0, 1), (0, 2), (1, 2)]
    assert projection_sets(2) == [(0,), (1,)]
    assert len(projection_sets(4)) == 6


def test_a_product_of_polytopes_pairs_vertices_in_product_order():
    tri = Polytope.from_vertices([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    seg = Polytope.box([-1.0], [2.0])
    P = product_polytope([tri, seg])
    assert P.vertices.shape == (6, 3)
    np.testing.assert_array_equal(P.vertices[:2], [np.r_[tri.vertices[0], seg.vertices[0]],
                                                   np.r_[tri.vertices[0], seg.vertices[1]]])
    np.testing.assert_allclose(np.linalg.norm(P.H, axis=1), 1.0)
    assert np.all(P.H @ P.vertices.T <= P.h[:, None] + 1e-12)            # every vertex inside
    assert not P.contains(np.array([[0.6, 0.6, 0.0]]))[0]                 # outside the triangle
    box = product_polytope([Polytope.box([0.0], [1.0]), Polytope.box([2.0, 3.0], [4.0, 5.0])])
    assert box.is_box and np.array_equal(box.bounding_box()[0], [0.0, 2.0, 3.0])


def test_every_refuted_pair_horizon_has_an_infeasible_joint_lp(highs_joint):
    refuted = [v for h, v in highs_joint.values() if h]
    assert len(refuted) > len(highs_joint) // 2                   # the screen refutes most of them here
    assert all(v.status == "infeasible" and v.margin < 0 for v in refuted)
    assert any(v.status == "edge" for _, v in highs_joint.values())


def test_the_joint_edges_are_those_of_the_joint_lps_alone(lifted, highs_joint):
    _, _, ps, _ = lifted
    assert ps.stats["n_joint_projected"] > 0 and ps.stats["n_projection_lps"] > 0
    least = {}
    for (i, j, L), (_, v) in sorted(highs_joint.items(), key=lambda kv: kv[0][2]):
        if v.status == "edge":
            least.setdefault((i, j), L)
    edges = {(i, j): (L, v) for i, j, L, v in zip(ps.src.tolist(), ps.dst.tolist(), ps.L.tolist(), ps.variant.tolist())}
    for (i, j), L in least.items():                  # every joint edge HiGHS finds is kept, at no larger L
        assert (i, j) in edges and edges[(i, j)][0] <= L
        if edges[(i, j)][1] == JOINT:
            assert edges[(i, j)][0] == L
    joint = {k for k, (_, v) in edges.items() if v == JOINT}
    assert joint and joint <= set(least)             # and every joint edge is one of them


def test_projected_cell_ids_kept_per_cell_are_those_recomputed(lifted):
    """The ids kept per joint cell (asked in any order, in pieces) are those :meth:`cell_ids` gives for the
    factor cells, and a fresh projection asked all at once numbers its cells the same way."""
    _, sysm, ps, joined = lifted
    cf = ps.structure.cell_factor
    cached, fresh = ProjectionScreen(ps.structure, sysm), ProjectionScreen(ps.structure, sysm)
    src, dst = joined.joint_src, joined.joint_dst
    for proj, ref in zip(cached.projections, fresh.projections):
        g = list(proj.groups)
        half = len(src) // 2
        got = np.concatenate([proj.ids_of(cf, src[:half]), proj.ids_of(cf, dst[:half]),
                              proj.ids_of(cf, src[half:]), proj.ids_of(cf, dst[half:])])
        want = np.concatenate([ref.cell_ids(cf[src[:half]][:, g]), ref.cell_ids(cf[dst[:half]][:, g]),
                               ref.cell_ids(cf[src[half:]][:, g]), ref.cell_ids(cf[dst[half:]][:, g])])
        np.testing.assert_array_equal(got, want)
        for i in np.unique(np.concatenate([src, dst])).tolist():        # an id is the product of its factor cells
            c = proj.cells[proj.ids_of(cf, np.array([i]))[0]]
            np.testing.assert_array_equal(c.vertices, product_polytope(
                [x.cells[k] for x, k in zip(proj.factors, cf[i, g])]).vertices)


def test_the_screen_solver_refutes_what_the_dual_reuse_solver_refutes(lifted):
    """The screen's solver (no proofs of clearly feasible projections) and the joint LPs' solver give the
    same refutations, and the screen refutes the same pair horizons with either."""
    _, sysm, ps, joined = lifted
    fast, full = ProjectionScreen(ps.structure, sysm), ProjectionScreen(ps.structure, sysm, solve_batch=DualReuseSolver())
    for L in range(1, L_MAX + 1):
        k = np.flatnonzero((joined.joint_box_mask & (np.uint64(1) << np.uint64(L - 1))) != 0)
        s, t = joined.joint_src[k], joined.joint_dst[k]
        np.testing.assert_array_equal(fast.refuted(s, t, L), full.refuted(s, t, L))
        for (n, L2), known in full._refuted.items():
            if L2 == L:
                for key, r in known.items():
                    assert fast._refuted[(n, L)][key] == r
    assert fast.n_lps == full.n_lps and fast.n_refuted == full.n_refuted > 0
    picked = {True: [], False: []}                  # projected problems the screen met, refuted or not
    for (n, L), known in sorted(full._refuted.items()):
        for key, r in known.items():
            picked[r].append((n, L, key))
    statuses = set()
    for n, L, (x, y) in picked[True][:15] + picked[False][:15]:
        proj = fast.projections[n]
        P = [proj.cells[x], proj.cells[y]]
        box = (np.minimum(*(c.bounding_box()[0] for c in P)), np.maximum(*(c.bounding_box()[1] for c in P)))
        prob = TubeProblem(proj.system, P[0], P[1], convex_hull_of(*P), proj.Z[x], L, box)
        a, b = _ScreenSolver()([prob])[0], DualReuseSolver()([prob])[0]
        statuses.add(b.status)
        assert (a.status == "infeasible") == (b.status == "infeasible")
        assert a.status == b.status or (b.status == "edge" and a.status == "unconfirmed" and a.tube is None)
    assert {"edge", "infeasible"} <= statuses


def test_projected_problems_kept_from_the_last_horizon_are_those_built_afresh(lifted):
    _, sysm, ps, joined = lifted
    kept, fresh = ProjectionScreen(ps.structure, sysm), ProjectionScreen(ps.structure, sysm)
    s, t = joined.joint_src, joined.joint_dst
    n_reused = 0
    for L in range(2, L_MAX + 1):
        before = {n: set(d) for n, d in kept._last.items()}
        fresh._last.clear()                                    # builds every problem
        np.testing.assert_array_equal(kept.refuted(s, t, L), fresh.refuted(s, t, L))
        assert kept._last.keys() == fresh._last.keys()
        for n, probs in kept._last.items():
            assert probs.keys() == fresh._last[n].keys()
            n_reused += len(before.get(n, set()) & set(probs))
            for key, p in probs.items():
                q = fresh._last[n][key]
                assert p.L == q.L == L and p.source is kept.projections[n].cells[key[0]]
                for P, Q in [(p.source, q.source), (p.target, q.target), (p.Z, q.Z), (p.safe, q.safe)]:
                    for a, b in [(P.vertices, Q.vertices), (P.H, Q.H), (P.h, Q.h)]:
                        np.testing.assert_array_equal(a, b)
                np.testing.assert_array_equal(np.stack(p.box), np.stack(q.box))
    assert n_reused > 0
