"""The exact check of a translated tube from one check of its canonical problem
(:func:`tubejax.lp.evidence.check_batch.translated_tube_violations`), held to the full exact
check of each member's own data (:func:`tubejax.lp.evidence.exact_tube_violation`)."""

import dataclasses
import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tubejax.abstraction import cross_sections
from tubejax.abstraction.translation_classes import TranslationClasses
from tubejax.lp.evidence import ExactTube, QArray, exact_tube_violation
from tubejax.lp.evidence.check import exact_terms
from tubejax.lp.evidence.check_batch import translated_tube_violations
from tubejax.lp.evidence.exact_problem import exact_tube_data
from tubejax.lp.evidence.translate_verdicts import _translated_many, canonical_problem
from tubejax.lp.evidence.verdict import highs_verdict
from tubejax.lp.declarations.tube_families import TubeVars, translation_groups, tube_residuals
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.problem import Pairs, pair_problems
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import box_grid, parse_grid_map


def _integrator():
    return LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))


def _double_integrator():
    """Look-ahead coordinates ``(p, s)``: ``A`` fixes ``p`` and ``s`` moved together."""
    return LinearSystem(A=np.array([[0.75, 0.25], [-0.25, 1.25]]), B=np.array([[0.125], [1.125]]),
                        U=box_input_set(1.0, 1), W=Ball(2, 0.02))


def _classes(d, s, zshape, L, reach=1.0):
    """Classes (two members or more) of exact translates among the pairs of ``d`` at ``L``."""
    pairs = [(i, j) for i in range(d.n_cells) for j in range(d.n_cells)
             if i != j and np.max(np.abs(d.cells[i].vertices.mean(0) - d.cells[j].vertices.mean(0))) <= reach]
    src, dst = np.array(pairs).T
    obstacle = d.obstacle_cases(src, dst)
    probs = pair_problems(d, s, cross_sections(d, zshape, 1.0), Pairs(src, dst, obstacle), L)
    rep = TranslationClasses(d, s).representatives(src, dst, obstacle, probs)
    out: dict = {}
    for k, r in enumerate(rep.tolist()):
        out.setdefault(r, []).append(probs[k])
    return [g for g in out.values() if len(g) >= 2]


def _tube_of(canon):
    """The canonical problem's tube (its exact proof where it has one) and whether it is an edge."""
    v = highs_verdict(canon)
    if v.status != "edge":
        return None
    return v.proof.exact if v.proof is not None and isinstance(v.proof.exact, ExactTube) else v.tube


CASES = [("integrator, box Z", lambda: (parse_grid_map("......\n......\n.#..#.\n......\n"), _integrator()), "box", (2, 4)),
         ("double integrator, cell Z", lambda: (box_grid([0.0, 0.0], [2.0, 2.0], [4, 4]), _double_integrator()),
          "cell", (2, 4, 6))]


@pytest.mark.parametrize("name, make, zshape, Ls", CASES, ids=[c[0] for c in CASES])
def test_each_member_gets_its_own_exact_violation(name, make, zshape, Ls):
    """For exact translates, the canonical problem's tube moved by each member's shift has the
    canonical problem's exact violation for the member's own data: feasible tubes and
    infeasible ones (eps shrunk) alike."""
    d, s = make()
    groups = translation_groups(s)
    n_checked = 0
    for L in Ls:
        for cls in _classes(d, s, zshape, L)[:16]:
            canon, _ = canonical_problem(cls[0])
            tube = _tube_of(canon)
            if tube is None:
                continue
            t = ExactTube.coerce(tube)
            shrunk = ExactTube(t.p, t.eps * QArray.from_fractions([Fraction(1, 2)]), t.u)
            shifts = np.array([canonical_problem(p)[1] for p in cls])
            for cand in (t, shrunk):
                got = translated_tube_violations(canon, cand, cls, shifts, groups)
                want = [exact_tube_violation(p, c) for p, c in zip(cls, _translated_many(cand, shifts))]
                assert got == want
                n_checked += len(cls)
            assert exact_tube_violation(canon, shrunk) > 0          # the infeasible candidate is one
    assert n_checked >= 20


def test_a_member_that_is_no_exact_translate_is_left_to_the_full_check():
    """A member whose target is moved by 1e-12, or whose ``L`` differs, or a shift that moves a
    group's axes differently, gets ``None``: the others keep the identity's answer."""
    d, s = parse_grid_map("......\n......\n.#..#.\n......\n"), _integrator()
    cls = next(c for L in (2, 3, 4) for c in _classes(d, s, "box", L)
               if len(c) >= 3 and _tube_of(canonical_problem(c[0])[0]) is not None)
    canon, _ = canonical_problem(cls[0])
    tube = _tube_of(canon)
    lo, hi = cls[1].target.bounding_box()
    moved = dataclasses.replace(cls[1], target=Polytope.box(lo + [1e-12, 0.0], hi + [1e-12, 0.0]))
    longer = dataclasses.replace(cls[2], L=cls[2].L + 1)
    probs = [cls[0], moved, longer]
    shifts = np.array([canonical_problem(p)[1] for p in probs])
    got = translated_tube_violations(canon, tube, probs, shifts, translation_groups(s))
    assert got[0] == exact_tube_violation(cls[0], _translated_many(tube, shifts[:1])[0])
    assert got[1] is None and got[2] is None
    bent = shifts[:1] + np.array([[0.0, 1.0]])                   # not the member's offset
    assert translated_tube_violations(canon, tube, cls[:1], bent, translation_groups(s)) == [None]


def test_groups_that_the_dynamics_do_not_fix_are_refused():
    """Told that the double integrator's ``p`` and ``s`` move on their own (they do not: ``A``
    fixes only their common move), the unit moves change the dynamics rows and every member is
    left to the full check."""
    d, s = box_grid([0.0, 0.0], [2.0, 2.0], [4, 4]), _double_integrator()
    cls = next(c for c in _classes(d, s, "cell", 2) if _tube_of(canonical_problem(c[0])[0]) is not None)
    canon, _ = canonical_problem(cls[0])
    shifts = np.array([canonical_problem(p)[1] for p in cls])
    assert translation_groups(s).tolist() == [0, 0]
    assert translated_tube_violations(canon, _tube_of(canon), cls, shifts, np.array([0, 1])) == [None] * len(cls)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(st.lists(st.integers(-8, 8), min_size=4, max_size=4), st.integers(-3, 3))
def test_family_residuals_are_affine_in_the_move(ab, k):
    """What the identity rests on: each row family's exact residual changes linearly when the
    source, the moving sets and ``p`` are moved by ``c`` (``eps``, ``u`` fixed), for any ``c``,
    not only the translations ``A`` fixes: ``r(c1 + k c2) - r(0) = (r(c1) - r(0)) + k (r(c2) - r(0))``."""
    d, s = box_grid([0.0, 0.0], [2.0, 2.0], [4, 4]), _double_integrator()
    pairs = Pairs([5], [6], d.obstacle_cases([5], [6]))
    prob = pair_problems(d, s, cross_sections(d, "cell", 1.0), pairs, 3)[0]
    d0 = exact_tube_data(prob)
    rng = np.random.default_rng(0)
    L, (nv, n) = d0.L, d0.V.shape
    t = ExactTube(QArray.from_floats(rng.normal(size=(L, n))), QArray.from_floats(rng.uniform(0.1, 1, L)),
                  QArray.from_floats(rng.normal(size=(L, nv, 1))))
    c1, c2 = np.array(ab[:2], float) / 8, np.array(ab[2:], float) / 4
    E = QArray.from_floats(np.array([np.zeros(n), c1, c2, c1 + k * c2]))
    regions = ("safe", "target")
    V = d0.V[None] + E[:, None, :]
    h = {r: d0.sets[r].h[None] + E @ QArray(d0.sets[r].H, 1).T for r in regions}
    x = TubeVars(t.p[None] + E[:, None, :], QArray.concatenate([t.eps[None]] * 4), QArray.concatenate([t.u[None]] * 4))
    for _, r, _ in tube_residuals(exact_terms(d0, V, h), x):
        moved = [(r[a] - r[0]).to_fractions() for a in (1, 2, 3)]
        assert np.array_equal(moved[2], moved[0] + k * moved[1])


def test_floats_become_rationals_over_the_least_power_of_two():
    for x in ([3.0, 6.0], [0.5, 0.25, -7.0], [0.0, -0.0], [5e-324, 1.0], [1e300, 0.1], [2.0 ** 53, 2.0 ** 53 + 2]):
        q = QArray.from_floats(np.array(x))
        assert q.to_fractions().tolist() == [Fraction(v) for v in x]
        assert math.gcd(q.den, *[int(v) for v in q.num.tolist()]) == 1
