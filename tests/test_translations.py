"""Translation classes (tubejax.abstraction.translation_classes): exact keys, and the abstraction settling the
translates of a clearly infeasible pair without solving them, with the same result."""

import numpy as np
import pytest

from tubejax.abstraction import TRANSLATE_PROVENANCE, build_abstraction, cross_sections
from tubejax.model.geometry import Ball
from tubejax.model.problem import Pairs, pair_problems
from tubejax.model.system import LinearSystem, box_input_set, exact_matrix, group_shift, translation_groups
from tubejax.abstraction.translation_classes import TranslationClasses, exact_difference
from tubejax.model.workspace import box_grid, parse_grid_map
from tubejax.lp.evidence.verdict import highs_solver

from one_by_one import assert_each_instance_on_its_own


def _groups(A):
    return translation_groups(exact_matrix(A, minus_identity=True)).tolist()


def test_translation_groups_are_exactly_the_translations_A_fixes():
    """Groups of axes that move alike under ``A c = c``, decided in rationals: every translation
    of a group is fixed by ``A`` exactly (checked in Fractions here), and a fixed axis that moves
    alone is its own group (the free axes of a shear, every axis of an integrator)."""
    from fractions import Fraction as F
    assert _groups(np.eye(3)) == [0, 1, 2]
    assert _groups([[1.0, 0.1], [0.0, 1.0]]) == [0, -1]
    assert _groups([[1.0, 0.0], [0.0, 1.0 + 1e-16]]) == [0, 1]         # 1 + 1e-16 == 1 in floats
    assert _groups([[1.0, 0.0], [0.0, 1.0 + 2.3e-16]]) == [0, -1]
    assert _groups([[0.0, -1.0], [1.0, 0.0]]) == [-1, -1]
    di = [[0.75, 0.25, 0, 0], [-0.25, 1.25, 0, 0], [0, 0, 0.75, 0.25], [0, 0, -0.25, 1.25]]
    assert _groups(di) == [0, 0, 2, 2]                  # (p, s) coordinates: p and s move together
    # A c = c for c = (1, 2): a fixed direction that is not "the same amount on some axes"
    assert _groups([[0.0, 0.5], [-2.0, 2.0]]) == [-1, -1]
    # rows that sum to 1 only in rounded floats (0.9 + 0.1, 1e-17 + 1) fix nothing
    assert _groups([[0.9, 0.1], [-0.1, 1.1]]) == [-1, -1]
    assert _groups([[0.75, 0.25], [-0.25, 1.25]]) == [0, 0]
    assert _groups([[1e-17, 1.0], [0.0, 1.0]]) == [-1, -1]     # A - I in floats would be [[-1, 1], [0, 0]]
    rng = np.random.default_rng(0)
    for _ in range(50):                                # every group's indicator is fixed, exactly
        A = np.eye(4)
        A[rng.integers(4), rng.integers(4)] += rng.choice([0.0, 0.25, -0.5])
        if rng.random() < 0.5:
            A[:, [0, 1]] = A[:, [0, 1]] + np.array([[0.25, -0.25]] * 4) * rng.integers(0, 2, (4, 1))
        g = np.array(_groups(A))
        for a in set(g[g >= 0].tolist()):
            one = (g == a).astype(int)
            assert all(sum(F(A[r, c]) * one[c] for c in range(4)) == one[r] for r in range(4))
    assert group_shift(np.array([[1.0, 2.0, 3.0, 4.0]]), np.array([0, 0, 2, -1])).tolist() == [[1.0, 1.0, 3.0, 0.0]]


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
    probs = pair_problems(d, s, cross_sections(d, "box", 1.0), Pairs(src, dst, obstacle), L)
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
        kw["solve_batch"] = highs_solver("openloop")
    on = build_abstraction(d, s, **kw)
    assert_each_instance_on_its_own(on, d, s, cross_sections(d, "box", 1.0), 6, method)   # the same instances
    assert on.stats["n_translated"] > 0
    assert on.stats["provenance"][TRANSLATE_PROVENANCE] == on.stats["n_translated"]
    assert all(e.provenance != TRANSLATE_PROVENANCE for e in on.edges)
    assert on.stats["n_lps"] == len(on.edges) + len(on.nonedges)


def test_a_shear_keeps_classes_along_its_fixed_axis_and_the_same_edges():
    A = np.array([[1.0, 0.2], [0.0, 1.0]])
    s = LinearSystem(A=A, B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1))
    d = parse_grid_map("......\n......\n")
    on = build_abstraction(d, s, L_max=5, progress=False)
    assert_each_instance_on_its_own(on, d, s, cross_sections(d, "box", 1.0), 5)
    assert on.stats["n_translated"] > 0


def test_the_double_integrator_has_classes_along_p_and_s_together_and_the_same_edges():
    """In look-ahead coordinates ``(p, s)`` the double integrator fixes ``p`` and ``s`` moving
    together (not each axis): pairs translated along that diagonal share a class, translated
    proofs prove their edges, and the system is the one without classes."""
    A = np.array([[0.75, 0.25], [-0.25, 1.25]])
    s = LinearSystem(A=A, B=np.array([[0.125], [1.125]]), U=box_input_set(1.0, 1), W=Ball(2, 0.02))
    d = box_grid([0.0, 0.0], [2.0, 2.0], [4, 4])
    o = np.array([c.vertices[0] for c in d.cells])
    at = {tuple(v): k for k, v in enumerate(o.tolist())}
    a, b = at[(0.0, 0.0)], at[(0.0, 0.5)]
    a2, b2 = at[(0.5, 0.5)], at[(0.5, 1.0)]                # (a, b) moved by (0.5, 0.5)
    a3, b3 = at[(0.5, 0.0)], at[(0.5, 0.5)]                # (a, b) moved by (0.5, 0): not fixed by A
    cl = TranslationClasses(d, s)
    assert cl.groups.tolist() == [0, 0]
    assert cl.group([a, a2, a3], [b, b2, b3], [False] * 3).tolist() == [0, 0, 2]
    on = build_abstraction(d, s, L_max=6, progress=False, zshape="cell")
    assert_each_instance_on_its_own(on, d, s, cross_sections(d, "cell", 1.0), 6)
    assert len(on.edges) > 0 and on.stats["n_translated"] > 0


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
    rp = RoundProblems(d, s, Z, Pairs(src, dst, obstacle), 4, 0.0, min_margin=0.1)
    assert len(rp) == 5 and rp._built == {}
    a = rp.take([3, 1])
    assert sorted(rp._built) == [1, 3]
    assert rp.take([1])[0] is a[1]                                 # each built once
    ref = pair_problems(d, s, Z, Pairs(src, dst, obstacle), 4, 0.0, min_margin=0.1)
    for got, want in zip(rp.take(range(5)), ref):
        for f in ("L", "eps_min", "min_margin"):
            assert getattr(got, f) == getattr(want, f)
        for f in ("source", "target", "safe", "Z"):
            assert np.array_equal(getattr(got, f).vertices, getattr(want, f).vertices)
    cl = TranslationClasses(d, s)
    assert cl.representatives_of_round(rp).tolist() == cl.representatives(src, dst, obstacle, ref).tolist()
