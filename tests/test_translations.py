"""Translation classes (tubejax.abstraction.translations): exact keys, and the abstraction settling the
translates of a clearly infeasible pair without solving them, with the same result."""

import numpy as np
import pytest

from tubejax.abstraction import TRANSLATE_PROVENANCE, build_abstraction, cross_sections
from tubejax.model.geometry import Ball
from tubejax.model.problem import pair_problems
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.abstraction.translations import TranslationClasses, exact_difference, free_axes
from tubejax.model.workspace import box_grid, parse_grid_map


def test_free_axes_are_the_exactly_fixed_ones():
    assert free_axes(np.eye(3)).tolist() == [True, True, True]
    assert free_axes(np.array([[1.0, 0.1], [0.0, 1.0]])).tolist() == [True, False]
    assert free_axes(np.array([[1.0, 0.0], [0.0, 1.0 + 1e-16]])).tolist() == [True, True]   # 1 + 1e-16 == 1
    assert free_axes(np.array([[1.0, 0.0], [0.0, 1.0 + 2.3e-16]])).tolist() == [True, False]
    assert not free_axes(np.array([[0.0, -1.0], [1.0, 0.0]])).any()


def test_exact_difference_is_exact():
    from fractions import Fraction as F
    a = np.array([3.0, 1e16 + 2.0, 0.1, 2.1, np.inf])
    b = np.array([1.0, 0.5, 3.0, 1.1, 0.0])
    s, err, ok = exact_difference(a, b)
    assert ok.tolist() == [True, True, True, True, False]
    for k in range(4):
        assert F(s[k]) + F(err[k]) == F(a[k]) - F(b[k])
    assert err[0] == 0 and err[1] != 0 and err[3] == 0          # 2.1 - 1.1 is exactly 1 in floats


def _classes(d, s, pairs, obstacle=None, L=3):
    src, dst = np.array(pairs).T
    obstacle = np.zeros(len(src), bool) if obstacle is None else np.asarray(obstacle)
    probs = pair_problems(d, s, cross_sections(d, "box", 1.0), src, dst, L, obstacle)
    return TranslationClasses(d, s).representatives(src, dst, obstacle, probs).tolist()


def test_pairs_share_a_class_only_as_exact_translates(paper_system):
    d = parse_grid_map("....\n....\n")                       # cells 0-3 on one row, 4-7 on the next
    s = paper_system(0.2)
    # (0,1), (1,2), (5,6) are one offset; (0,2) another; (4,5) but in the obstacle case: its own
    assert _classes(d, s, [(0, 1), (1, 2), (0, 2), (5, 6), (4, 5)], [0, 0, 0, 0, 1]) == [0, 0, 2, 0, 4]
    # A moves along axis 1 (x+ = x + 0.1 y): only translations along axis 0 keep the problem, so
    # (0,1) and (1,2) (top row, y = 1) share a class, (5,6) (bottom row, y = 0) does not
    s2 = LinearSystem(A=np.array([[1.0, 0.1], [0.0, 1.0]]), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    assert [c.vertices[0][1] for c in d.cells] == [1.0] * 4 + [0.0] * 4
    assert _classes(d, s2, [(0, 1), (1, 2), (5, 6)]) == [0, 0, 2]


def test_keys_are_exact_where_floats_round(paper_system):
    """Cells at x = 0.1, 1.1, 2.1: in floats 1.1 - 0.1 is not 1 but 2.1 - 1.1 is, so cell 0 is a
    different shape from cells 1 and 2 (as exact rationals): no class joins them; cells at 0.5,
    1.5, 2.5 (dyadic) are exact translates."""
    s = paper_system(0.2)
    d = box_grid([0.1, 0.0], [3.1, 1.0], [3, 1])
    assert [c.vertices[0][0] for c in d.cells] == [0.1, 1.1, 2.1]
    assert _classes(d, s, [(0, 1), (1, 2)], L=2) == [0, 1]
    d2 = box_grid([0.5, 0.0], [3.5, 1.0], [3, 1])
    assert _classes(d2, s, [(0, 1), (1, 2)], L=2) == [0, 0]


@pytest.mark.parametrize("method", ["tube", "openloop"])
def test_the_rule_changes_no_edge_and_solves_fewer_lps(paper_system, method):
    d = parse_grid_map(".....\n.#...\n.....\n...#.\n")
    s = paper_system(0.2)
    kw = dict(L_max=6, progress=False, method=method)
    if method == "openloop":
        from tubejax.lp.evidence.verdict import openloop_solve_batch
        kw["solve_batch"] = openloop_solve_batch
    on = build_abstraction(d, s, translations=True, **kw)
    off = build_abstraction(d, s, translations=False, **kw)
    assert [(e.src, e.dst, e.L) for e in on.edges] == [(e.src, e.dst, e.L) for e in off.edges]
    assert on.stats["n_translated"] > 0 and off.stats["n_translated"] == 0
    assert on.stats["provenance"][TRANSLATE_PROVENANCE] == on.stats["n_translated"]
    assert all(e.provenance != TRANSLATE_PROVENANCE for e in on.edges)
    assert on.stats["n_lps"] == off.stats["n_lps"]           # the same instances settled
    assert on.stats["verdicts"] == off.stats["verdicts"]


def test_a_shear_keeps_classes_along_its_fixed_axis_and_the_same_edges():
    A = np.array([[1.0, 0.2], [0.0, 1.0]])
    s = LinearSystem(A=A, B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1))
    d = parse_grid_map("......\n......\n")
    on = build_abstraction(d, s, L_max=5, progress=False, translations=True)
    off = build_abstraction(d, s, L_max=5, progress=False, translations=False)
    assert [(e.src, e.dst, e.L) for e in on.edges] == [(e.src, e.dst, e.L) for e in off.edges]
    assert on.stats["n_translated"] > 0


def test_no_fixed_axis_means_no_classes():
    R = np.array([[0.0, -1.0], [1.0, 0.0]])
    s = LinearSystem(A=R, B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.05))
    ts = build_abstraction(parse_grid_map("...\n...\n"), s, L_max=3, progress=False)
    assert ts.stats["n_translated"] == 0


def test_round_problems_build_only_what_is_taken_and_equal_pair_problems(paper_system):
    from tubejax.model.problem import RoundProblems
    d = parse_grid_map(".....\n.#...\n.....\n")
    s = paper_system(0.2)
    src, dst = np.array([0, 1, 2, 5, 7]), np.array([1, 2, 3, 6, 8])
    obstacle = d.obstacle_cases(src, dst)
    Z = cross_sections(d, "box", 1.0)
    rp = RoundProblems(d, s, Z, src, dst, 4, obstacle, 0.0, min_margin=0.1)
    assert len(rp) == 5 and rp._built == {}
    a = rp.take([3, 1])
    assert sorted(rp._built) == [1, 3]
    assert rp.take([1])[0] is a[1]                                 # each built once
    ref = pair_problems(d, s, Z, src, dst, 4, obstacle, 0.0, min_margin=0.1)
    for got, want in zip(rp.take(range(5)), ref):
        for f in ("L", "eps_min", "min_margin"):
            assert getattr(got, f) == getattr(want, f)
        for f in ("source", "target", "safe", "Z"):
            assert np.array_equal(getattr(got, f).vertices, getattr(want, f).vertices)
    cl = TranslationClasses(d, s)
    assert cl.representatives_of_round(rp).tolist() == cl.representatives(src, dst, obstacle, ref).tolist()
