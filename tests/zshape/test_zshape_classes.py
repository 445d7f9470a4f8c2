"""Learning with translation classes optimises the same objective as on every pair, at the cost of the
classes; and a start that already certifies every pair is kept without a step.

The two runs are not bit-identical: a degenerate margin LP has several optimal duals, and HiGHS may
return different ones for a pair and its translate, so the envelope gradients (equally valid) differ
slightly and the iterates drift apart by ~1e-3 (objective up to ~3e-3 relative) over a few steps.
From the ``thin`` start, whose first steps cross many such degenerate optima in state-space
margins, the drift reaches ~2e-2 within four steps; the classes are compared from ``wide``.

Learning on every pair is the learner with each pair its own class (:func:`each_pair_alone`, a test
device: the library has no switch for it).
"""

import contextlib

import numpy as np
import pytest

from tubejax.model.geometry import Ball, Polytope
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.abstraction.translation_classes import pair_classes
from tubejax.model.workspace.gridmap import parse_grid_map
from tubejax.analyses.zshape import LearnOptions, learn_z
from tubejax.analyses.zshape import learn as learn_module
from tubejax.analyses.zshape.learn_run import learn_table
from tubejax.analyses.zshape.starts import CERTIFIED_TOL

PAPER = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
ROTATION = LinearSystem(A=np.array([[1.0, 0.1], [-0.1, 1.0]]), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
GRID = "....\n...."
OPTS = LearnOptions(steps=4, learning_rate=0.1)


@contextlib.contextmanager
def each_pair_alone():
    """The learner with every candidate pair its own translation class (one LP per pair)."""
    def alone(decomp, system, src, dst, ints):
        n = len(src)
        return np.arange(n), np.arange(n), np.ones(n, dtype=np.int64)

    with pytest.MonkeyPatch.context() as m:
        m.setattr(learn_module, "pair_classes", alone)
        yield


def thin(i, j):
    return Polytope.box([-1.0, -0.2], [1.0, 0.2])


def wide(i, j):
    return Polytope.box([-0.2, -1.0], [0.2, 1.0])


def assert_same_learning(a, b):
    assert np.array_equal(a.pairs, b.pairs) and np.array_equal(a.L, b.L)
    np.testing.assert_allclose(a.start_margins, b.start_margins, atol=1e-12)     # translates: equal margins
    assert a.history[0]["objective"] == pytest.approx(b.history[0]["objective"], rel=1e-12)
    assert [h["certified"] for h in a.history] == [h["certified"] for h in b.history]
    np.testing.assert_allclose([h["objective"] for h in a.history], [h["objective"] for h in b.history],
                               rtol=1e-2)                                        # drift: see above
    assert np.sum(a.margins >= -CERTIFIED_TOL) == np.sum(b.margins >= -CERTIFIED_TOL)   # as the learner counts


@pytest.mark.parametrize("mode", ["learned", "learned_pair"])
def test_classes_learn_the_same_z_with_fewer_lps(mode):
    decomp = parse_grid_map(GRID)
    a = learn_z(decomp, PAPER, mode=mode, init=wide, options=OPTS, progress=False)
    with each_pair_alone():
        b = learn_z(decomp, PAPER, mode=mode, init=wide, options=OPTS, progress=False)
    assert a.history[-1]["objective"] > a.history[0]["objective"]        # the wide start moves
    assert_same_learning(a, b)
    assert b.n_classes == len(b.pairs) == 56
    assert a.n_classes < 25 and a.n_lps * 2 < b.n_lps
    if mode == "learned_pair":                                          # a class is one group: one Z
        for g in range(a.n_classes):
            members = np.flatnonzero(a.group_of_pair == g)
            assert len(members) >= 1
            assert np.all(a.margins[members] == a.margins[members[0]])


def test_pairs_with_different_starts_are_not_joined():
    decomp = parse_grid_map(GRID)

    def mixed(i, j):                      # the start depends on the source column: translates differ
        return thin(i, j) if decomp.cells[i].vertices[0][0] < 2 else wide(i, j)

    a = learn_z(decomp, PAPER, mode="learned_pair", init=mixed, options=OPTS, progress=False)
    with each_pair_alone():
        b = learn_z(decomp, PAPER, mode="learned_pair", init=mixed, options=OPTS, progress=False)
    assert_same_learning(a, b)
    plain = learn_z(decomp, PAPER, mode="learned_pair", init=thin, options=OPTS, progress=False)
    assert a.n_classes > plain.n_classes
    left = np.array([decomp.cells[i].vertices[0][0] < 2 for i, _ in a.pairs])
    for g in range(a.n_classes):                                        # one start per class
        assert len(set(left[a.group_of_pair == g].tolist())) == 1


def test_a_rotating_a_forms_no_classes():
    decomp = parse_grid_map("...")
    first, of, size = pair_classes(decomp, ROTATION, [0, 1, 1, 2], [1, 2, 0, 1])
    assert len(first) == 4 and np.all(size == 1)
    first, of, size = pair_classes(decomp, PAPER, [0, 1, 1, 2], [1, 2, 0, 1])
    assert first.tolist() == [0, 2] and of.tolist() == [0, 0, 1, 1] and size.tolist() == [2, 2]


def test_a_start_that_certifies_every_pair_is_kept_without_a_step():
    decomp = parse_grid_map(GRID)
    res = learn_z(decomp, PAPER, init="box", options=LearnOptions(steps=5, require_gain=True), progress=False)
    assert len(res.history) == 1 and res.history[0]["certified"] == len(res.pairs)
    np.testing.assert_array_equal(res.z, res.start_z)
    more = learn_z(decomp, PAPER, init="box", options=LearnOptions(steps=2), progress=False)
    assert len(more.history) == 3                                       # without require_gain it steps


def test_the_table_is_the_same_with_and_without_classes():
    decomp = parse_grid_map(GRID)
    opts = LearnOptions(steps=3)
    a = learn_table(decomp, PAPER, "learned_pair", init="cell", options=opts._replace(L_max=6), progress=False)
    with each_pair_alone():
        b = learn_table(decomp, PAPER, "learned_pair", init="cell", options=opts._replace(L_max=6), progress=False)
    assert sorted(a.pairs) == sorted(b.pairs)
    for k in a.pairs:
        np.testing.assert_allclose(a.pairs[k].vertices, b.pairs[k].vertices, atol=1e-8)
    fam = a.learning["families"][0]
    assert fam["n_classes"] < fam["n_pairs"]
    assert b.learning["families"][0]["n_classes"] == fam["n_pairs"]
