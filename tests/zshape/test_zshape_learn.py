"""The optax learner: it recovers from a bad start, improves where the fixed shapes fall short, keeps
Z's invariants, is deterministic, and every learned edge is verified and a subset of exact2d's."""

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.reachability.exact2d import exact_edges
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set
from tubejax.model.workspace.gridmap import load_grid_map, parse_grid_map
from tubejax.model.workspace.polygon import parse_polygon_workspace_text
from tubejax.analyses.zshape import (LearnOptions, ZTable, learn_pair_z, learn_z, pair_abstraction, polytope_from_z,
                                     table_from_learned, use_z_table)

PAPER = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
L1 = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2), W=Ball(2, 0.2))
TRIANGLES = "boundary: [[0, 0], [3, 0], [3, 2], [0, 2]]\nobstacles: []\nmax_area: 0.8\n"


def thin(i, j):
    return Polytope.box([-1.0, -0.2], [1.0, 0.2])


def n_edges(decomp, system, result, L_max=10):
    with use_z_table(table_from_learned(result, decomp)):
        ts = build_abstraction(decomp, system, zshape="learned", L_max=L_max, progress=False)
    return ts


def assert_within_exact(edges, exact):
    for e in edges:
        assert (e.src, e.dst) in exact, f"{e.src}->{e.dst} is not an exact2d edge"
        assert e.L >= exact[(e.src, e.dst)][0]


def test_learning_beats_a_thin_rectangle():
    decomp = parse_grid_map("...\n...")
    box = build_abstraction(decomp, PAPER, zshape="box", progress=False)
    with use_z_table(ZTable("learned", 2, [(decomp.cells[0].vertices, thin(0, 1).vertices)])):
        bad = build_abstraction(decomp, PAPER, zshape="learned", progress=False)
    assert bad.n_edges < box.n_edges                              # the thin start loses transitions
    res = learn_z(decomp, PAPER, init=thin, options=LearnOptions(steps=6, learning_rate=0.1), progress=False)
    assert res.history[-1]["objective"] > res.history[0]["objective"]
    ts = n_edges(decomp, PAPER, res)
    assert ts.n_edges >= box.n_edges
    assert np.all(ts.verify() <= 1e-9)
    assert_within_exact(ts.edges, exact_edges(decomp, PAPER, 10))


def test_learned_edges_on_the_one_norm_corridor_are_exact2d_edges(corridor_path):
    decomp = load_grid_map(corridor_path)
    res = learn_z(decomp, L1, init="box", options=LearnOptions(steps=3), progress=False)
    assert len(res.pairs) == 102 and len(res.z) == 1              # one cell shape: one shared Z
    ts = n_edges(decomp, L1, res)
    assert ts.n_edges >= 44                                       # never below its start (box: 44)
    assert np.all(ts.verify() <= 1e-9)
    assert {e.proof for e in ts.edges} == {"exact"}
    assert_within_exact(ts.edges, exact_edges(decomp, L1, 10))


def test_per_pair_z_gains_on_triangles_and_stays_sound():
    decomp = parse_polygon_workspace_text(TRIANGLES)
    cell = build_abstraction(decomp, PAPER, zshape="cell", progress=False)
    exact = exact_edges(decomp, PAPER, 10)
    assert cell.n_edges < len(exact)                              # the fixed shape falls short
    Z = learn_pair_z(decomp, PAPER, init="cell",
                     options=LearnOptions(steps=8, learning_rate=0.1, horizon="best"), progress=False)
    assert len(Z) == 56 and all(z.n_vertices == 3 and np.all(z.h > 0) for z in Z.values())
    pa = pair_abstraction(decomp, PAPER, Z)
    assert pa.stats["n_edges"] > cell.n_edges
    assert np.all(pa.verify() <= 1e-9)
    assert_within_exact(pa.edges, exact)
    assert pa.stats["proof"]["float"] == 0


def test_invariants_and_determinism():
    decomp = parse_grid_map("..\n..")
    opts = LearnOptions(steps=4, learning_rate=0.2, jitter=0.05, seed=7)
    a = learn_z(decomp, PAPER, mode="learned_pair", init="box", options=opts, progress=False)
    b = learn_z(decomp, PAPER, mode="learned_pair", init="box", options=opts, progress=False)
    c = learn_z(decomp, PAPER, mode="learned_pair", init="box", options=opts._replace(seed=8), progress=False)
    np.testing.assert_array_equal(a.z, b.z)
    assert a.n_compiles == 1                                      # one executable for every step
    assert [h["objective"] for h in a.history] == [h["objective"] for h in b.history]
    assert not np.array_equal(a.start_z, c.start_z)
    for z in np.concatenate([a.z, a.start_z]):
        P = polytope_from_z(a.family, z)                          # 0 interior, 4 vertices, same order
        assert P.n_vertices == 4 and np.all(P.h > 0)
        np.testing.assert_array_equal(Polytope.from_vertices(z).vertices, z)
        np.testing.assert_allclose(z.mean(axis=0), 0, atol=1e-12)   # translation removed
        np.testing.assert_allclose(np.mean(np.sum(z ** 2, axis=1)), 2.0)   # scale fixed
    assert (a.margins >= -1e-9).sum() >= (a.start_margins >= -1e-9).sum()


def test_bad_arguments():
    decomp = parse_grid_map("..\n..")
    with pytest.raises(ValueError, match="mode"):
        learn_z(decomp, PAPER, mode="box")
    with pytest.raises(ValueError, match="horizon"):
        learn_z(decomp, PAPER, options=LearnOptions(horizon="first"))
    with pytest.raises(ValueError, match="learning_rate"):
        learn_z(decomp, PAPER, options=LearnOptions(learning_rate=0.0))
    with pytest.raises(ValueError, match="'target'"):
        learn_z(decomp, PAPER, init="target", options=LearnOptions(steps=0))
    with pytest.raises(ValueError, match="no candidate"):
        learn_z(decomp, PAPER, pairs=[(0, 0)])
