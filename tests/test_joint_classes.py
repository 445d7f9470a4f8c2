"""The product path's joint LPs solved by exact translation class (``joint_pairs`` with
:func:`~tubejax.abstraction.translation_classes.solve_by_class` and
:class:`~tubejax.abstraction.joint_duals.DualReuseSolver`'s translated proofs).

Compared with one HiGHS solve and confirmation per problem (``highs_solve_batch``): the same
statuses and the same edges at the same least ``L``; every translated proof checked again exactly
against the member's own rebuilt problem; a member whose data are not a translate of its
representative's is solved on its own; the product system with translated joint edges passes
``verify`` and survives the product file.
"""

import numpy as np
import pytest

import tubejax as tj
from tubejax.__main__ import main as cli
from tubejax.abstraction.joint_duals import DualReuseSolver
from tubejax.abstraction.product_abstraction import JOINT, build_product_abstraction
from tubejax.abstraction.product_joint_lps import joint_pairs
from tubejax.abstraction.product_join import join_factors
from tubejax.abstraction.product_store import ProductProblem, load_product, save_product
from tubejax.abstraction.translation_classes import TRANSLATE_PROVENANCE, TranslationClasses, solve_by_class
from tubejax.lp.declarations.tube_lp import tube_violation
from tubejax.lp.evidence.check import exact_tube_violation
from tubejax.lp.evidence.check_batch import exact_tube_violations
from tubejax.lp.evidence.verdict import TRANSLATED_PROOF, VERIFY_TOL, highs_solve_batch, highs_verdict
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.problem import Pairs, TubeProblem, pair_problems
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import box_grid
from tubejax.model.zshape.kinds import cross_sections
from tubejax.verify.product_check import verify_product

L_MAX = 6


def _system():
    return LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1))


@pytest.fixture(scope="module")
def corners():
    """A 9 x 4 grid with the same two obstacles every 3 cells: the pairs around one obstacle's corner
    (blocked bounding box, free hull: joint LPs) are exact translates of those around the others."""
    obs = [([2 + 3 * k, y], [3 + 3 * k, y + 1]) for k in range(3) for y in (0, 3)]
    d = box_grid([0, 0], [9, 4], [9, 4], obstacles=obs)
    sysm = _system()
    return d, sysm, build_product_abstraction(d, sysm, zshape="box", L_max=L_MAX)


@pytest.fixture(scope="module")
def grid_translates():
    """Problems of a 5 x 5 grid, every pair at offset (1, 1), (2, 1) or (2, 2) cells, at L = 1..3
    (edges and infeasible ones), with their pairs: ``(d, sysm, [(L, src, dst, problems)])``."""
    d = box_grid([0, 0], [5, 5], [5, 5])
    sysm = _system()
    Z = cross_sections(d, "box", 1.0)
    c = np.array([P.vertices.mean(axis=0) for P in d.cells])
    pairs = [(i, j) for i in range(d.n_cells) for j in range(d.n_cells)
             if tuple(np.abs(c[j] - c[i])) in {(1.0, 1.0), (2.0, 1.0), (2.0, 2.0)}]
    s, t = (np.array(x) for x in zip(*pairs))
    return d, sysm, [(L, s, t, pair_problems(d, sysm, Z, Pairs(s, t, np.zeros(len(s), bool)), L)) for L in (1, 2, 3)]


def _assert_proved_on_own_data(probs, verdicts):
    """Every translated proof holds, exactly and in float64, for the member's own problem."""
    n = 0
    for p, v in zip(probs, verdicts):
        if v.provenance == TRANSLATED_PROOF:
            assert v.status == "edge" and v.proof.level == "exact"
            assert exact_tube_violation(p, v.proof.exact if v.proof.exact is not None else v.tube) <= 0
            assert tube_violation(p, v.tube) <= VERIFY_TOL
            n += 1
    return n


def test_classes_give_the_one_by_one_verdicts(grid_translates):
    d, sysm, rounds = grid_translates
    classes = TranslationClasses(d, sysm)
    solver = DualReuseSolver()
    n_translated = n_moved = 0
    for L, s, t, probs in rounds:
        got, moved = solve_by_class(solver, classes, probs, s, t, np.zeros(len(s), bool))
        want = highs_solve_batch(probs)
        assert [v.status for v in got] == [v.status for v in want]
        for g, w in zip(got, want):
            if g.provenance != TRANSLATED_PROOF and g.provenance != TRANSLATE_PROVENANCE and w.status == "edge":
                assert g.margin == w.margin                  # solved on its own: HiGHS's own answer
            elif g.provenance == TRANSLATE_PROVENANCE:
                assert g.status == "infeasible" and w.margin < 0
        n_translated += _assert_proved_on_own_data(probs, got)
        n_moved += moved
    assert n_translated == solver.n_translated > 0 and n_moved > 0


def test_a_member_that_is_not_a_translate_is_solved_on_its_own(grid_translates):
    d, sysm, rounds = grid_translates
    L, s, t, probs = rounds[-1]
    want = highs_solve_batch(probs)
    rep = TranslationClasses(d, sysm).representatives(s, t, np.zeros(len(s), bool), probs)
    a = next(a for a in range(len(probs)) if rep[a] != a and want[a].status == "edge")
    r, member = int(rep[a]), probs[a]
    far = member.target.vertices + 0.25                      # the target moved a little: not a translate
    moved = TubeProblem(member.system, member.source, Polytope(far, member.target.H, np.max(far @ member.target.H.T,
                        axis=0)), member.safe, member.Z, member.L, member.box, member.eps_min, member.min_margin)
    solver = DualReuseSolver()
    rep_verdict = solver([probs[r]])[0]
    assert rep_verdict.status == "edge" and rep_verdict.proof.level == "exact"
    got = solver([member, moved], likely_edges=[[0, 1]], representatives=[(probs[r], rep_verdict)])
    assert got[0].provenance == TRANSLATED_PROOF and solver.n_translated == 1
    assert got[1].provenance != TRANSLATED_PROOF and solver.n_solved == 2       # the representative and `moved`
    own = highs_verdict(moved)
    assert got[1].status == own.status and got[1].margin == own.margin
    # the representative's exact tube moved by the member's offset (`moved` has the member's source) fails on its data
    tube = got[0].proof.exact if got[0].proof.exact is not None else got[0].tube
    assert exact_tube_violation(moved, tube) > 0
    # the batched check with the members' data derived from the representative's is each one's own check
    for members in ([member], [member, moved]):
        assert exact_tube_violations(members, [tube] * len(members), reference=probs[r]) == \
            [exact_tube_violation(m, tube) for m in members]


def test_joint_pairs_by_class_match_one_by_one_highs(corners):
    d, sysm, ps = corners
    joined = join_factors(d, ps.structure, ps.tables)
    solver = DualReuseSolver()
    verdicts, L_of, _, _ = joint_pairs(d, sysm, ps.Z, joined, L_MAX, 0.0, solver)
    want, open_ = {}, np.ones(len(joined.joint_src), bool)
    for L in range(1, L_MAX + 1):
        k = np.flatnonzero(open_ & ((joined.joint_box_mask & (np.uint64(1) << np.uint64(L - 1))) != 0))
        s, t = joined.joint_src[k], joined.joint_dst[k]
        for kk, i, j, v in zip(k, s.tolist(), t.tolist(),
                               highs_solve_batch(pair_problems(d, sysm, ps.Z, Pairs(s, t, np.zeros(k.size, bool)), L))):
            if v.status == "edge":
                want[(i, j)], open_[kk] = L, False
    assert L_of == want and len(want) > 0
    assert solver.n_translated > 0
    for (i, j), v in verdicts.items():
        if v.provenance == TRANSLATED_PROOF:
            p = pair_problems(d, sysm, ps.Z, Pairs([i], [j], [False]), L_of[(i, j)])[0]
            assert _assert_proved_on_own_data([p], [v]) == 1


def test_translated_joint_edges_pass_verify_and_the_product_file(corners, tmp_path):
    d, sysm, ps = corners
    assert ps.stats["n_joint_translated"] > 0
    joint = ps.variant == JOINT
    assert any(ps.joint[(int(i), int(j))].provenance == TRANSLATED_PROOF for i, j in zip(ps.src[joint], ps.dst[joint]))
    assert verify_product(ps).ok
    save_product(ps, tmp_path)
    back = load_product(tmp_path, ProductProblem(d, sysm, ps.Z))
    for key, v in ps.joint.items():
        if v.status == "edge":
            w = back.joint[key]
            assert w.provenance == v.provenance and w.margin == v.margin and w.proof.level == v.proof.level
            for x, y in zip(v.tube, w.tube):
                np.testing.assert_array_equal(np.asarray(x), y)
    assert verify_product(back).ok


def test_python_m_tubejax_verify_passes_a_run_with_translated_joint_edges(tmp_path, capsys):
    obs = [([2 + 3 * k, y], [3 + 3 * k, y + 1]) for k in range(3) for y in (0, 3)]
    ts = tj.abstract(tj.box_grid([0, 0], [9, 4], [9, 4], obstacles=obs), _system(), zshape="box", L_max=L_MAX,
                     solver="highs", product=True)
    ps = ts.product
    assert any(v.provenance == TRANSLATED_PROOF for v in ps.joint.values())
    ts.save(tmp_path)
    assert cli(["verify", str(tmp_path), "--quiet"]) == 0
    assert "verify OK" in capsys.readouterr().out
