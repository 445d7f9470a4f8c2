"""Confirming many exact translates together (tubejax.lp.evidence.translate_verdicts): warm-started HiGHS,
batched builders and checks, translated proofs -- each answer equal to the one-by-one path."""

import dataclasses
from concurrent.futures import Future
from fractions import Fraction

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction, cross_sections
from tubejax.lp.evidence import ExactTube, QArray, exact_tube_violation
from tubejax.lp.evidence.check_batch import exact_tube_violations, row_max_batch
from tubejax.lp.evidence.rational import row_max
from tubejax.lp.evidence.translate_verdicts import (WARM_COLD_BAND, _settled_many, _translated_many,
                                            TranslateChecks, canonical_problem, confirm_translates_with_highs,
                                            highs_translate_verdicts)
from tubejax.lp.evidence.verdict import TRANSLATE_EDGE, TRANSLATED_PROOF, highs_verdict
from tubejax.lp.declarations.tube_lp import build_tube_lp, tube_violation
from tubejax.lp.declarations.tube_variables import Tube
from tubejax.lp.declarations.tube_lp_batch import build_tube_lps, tube_violations
from tubejax.lp.engines.highs import solve_margin_lp, solve_margin_lp_from
from tubejax.lp.batch.sign_mode import _direct_groups, split_future
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.problem import Pairs, pair_problem, pair_problems
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.zshape.kinds import make_z
from tubejax.abstraction.translation_classes import TranslationClasses
from tubejax.model.workspace import parse_grid_map

from one_by_one import assert_each_instance_on_its_own

MAP = "......\n......\n.#..#.\n......\n"


def _class_groups(d, s, L, pairs=None):
    """Groups (size >= 2) of exact translates among the pairs of ``d`` at horizon ``L``."""
    if pairs is None:
        pairs = [(i, j) for i in range(d.n_cells) for j in range(d.n_cells)
                 if i != j and np.max(np.abs(d.cells[i].vertices.mean(0) - d.cells[j].vertices.mean(0))) <= 3.0]
    src, dst = np.array(pairs).T
    obstacle = d.obstacle_cases(src, dst)
    probs = pair_problems(d, s, cross_sections(d, "box", 1.0), Pairs(src, dst, obstacle), L)
    rep = TranslationClasses(d, s).representatives(src, dst, obstacle, probs)
    groups = {}
    for k, r in enumerate(rep.tolist()):
        groups.setdefault(r, []).append(probs[k])
    return [g for g in groups.values() if len(g) >= 2]


@pytest.fixture(scope="module")
def groups():
    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    d = parse_grid_map(MAP)
    return [g for L in (2, 4, 10) for g in _class_groups(d, s, L)]      # at L = 10, 3 cells: zero margins


def test_solves_from_a_translates_basis_equal_cold_ones(groups):
    for g in groups[:12]:
        start = solve_margin_lp(build_tube_lp(g[0]), basis_min_margin=-np.inf)
        for p in g[1:]:
            lp = build_tube_lp(p)
            a = solve_margin_lp_from(lp, (start.col_status, start.row_status), basis_min_margin=-1.0)
            b = solve_margin_lp(lp, basis_min_margin=-1.0)
            assert a.status == b.status == "Optimal"
            assert abs(a.margin - b.margin) <= 1e-12
    lp = build_tube_lp(groups[0][0])
    other = [g for g in groups if build_tube_lp(g[0]).G.shape != lp.G.shape][0]
    wrong = solve_margin_lp(build_tube_lp(other[0]), basis_min_margin=-np.inf)
    a = solve_margin_lp_from(lp, (wrong.col_status, wrong.row_status))      # another shape: solved cold
    assert abs(a.margin - solve_margin_lp(lp).margin) <= 1e-12


def test_the_canonical_problem_is_the_same_for_every_member_bit_for_bit(groups):
    for g in groups:
        c0, _ = canonical_problem(g[0])
        lp0 = build_tube_lp(c0)
        for p in g[1:]:
            c, shift = canonical_problem(p)
            lp = build_tube_lp(c)
            for f in ("G", "g", "lb", "ub"):
                assert np.array_equal(getattr(lp, f), getattr(lp0, f)), f
            assert np.array_equal(c.source.vertices + shift, p.source.vertices)


def test_a_members_verdict_does_not_depend_on_its_group(groups):
    """Chunking, memory budgets and resumed runs put a translate in other groups: its verdict,
    margin and tube stay the same, bit for bit."""
    for g in groups[::2]:
        if len(g) < 3:
            continue
        whole = highs_translate_verdicts(g)
        part = highs_translate_verdicts(g[-2:][::-1])[::-1]
        for a, b in zip(whole[-2:], part):
            assert a.status == b.status and a.margin == b.margin
            assert (a.tube is None) == (b.tube is None)
            if a.tube is not None:
                assert all(np.array_equal(x, y) for x, y in zip(a.tube, b.tube))
                assert a.proof.level == b.proof.level


def test_batched_builder_equals_the_dense_builder_bit_for_bit(groups):
    mixed = groups[0][:3] + groups[-1][:3] + groups[1][:2]         # other matrices are built one by one
    for g in [groups[0], groups[-1], mixed]:
        for a, b in zip(build_tube_lps(g), [build_tube_lp(p) for p in g]):
            for f in ("G", "g", "row_kind", "G_hard", "g_hard", "lb", "ub", "t_max", "index"):
                assert np.array_equal(getattr(a, f), getattr(b, f)), f
    lp = build_tube_lps(groups[0])[0]
    with pytest.raises(ValueError):
        lp.G[0, 0] = 1.0                                            # shared: read-only


def _tubes(g, rng, scale):
    out = []
    for p in g:
        v = highs_verdict(p)
        L, n, nv, m = int(p.L), 2, p.source.n_vertices, 2
        t = v.tube if v.tube is not None else Tube(np.zeros((L, n)), np.ones(L), np.zeros((L, nv, m)))
        out.append(Tube(t.p + rng.normal(0, scale, t.p.shape), t.eps, t.u))
    return out


@pytest.mark.parametrize("scale", [0.0, 1e-3, 0.1])
def test_batched_float_check_equals_the_one_by_one_check(groups, scale):
    rng = np.random.default_rng(1)
    for g in groups[::3]:
        tubes = _tubes(g, rng, scale)
        assert np.array_equal(tube_violations(g, tubes), [tube_violation(p, t) for p, t in zip(g, tubes)])
    g = groups[0]
    tubes = _tubes(g, rng, 0.0)
    tubes[1] = tubes[1]._replace(p=np.full_like(tubes[1].p, np.nan))
    tubes[2] = tubes[2]._replace(eps=tubes[2].eps[:-1])                   # wrong shape
    v = tube_violations(g, tubes)
    assert v[1] == np.inf and v[2] == np.inf and np.isfinite(v[0])


@pytest.mark.parametrize("scale", [0.0, 1e-3, 0.1])
def test_batched_exact_check_equals_the_one_by_one_check(groups, scale):
    rng = np.random.default_rng(2)
    for g in groups[::2]:
        tubes = _tubes(g, rng, scale)
        assert exact_tube_violations(g, tubes) == [exact_tube_violation(p, t) for p, t in zip(g, tubes)]
        exact = [ExactTube(QArray.from_floats(t.p) + QArray.from_fractions([Fraction(1, 3)]), QArray.from_floats(t.eps),
                           QArray.from_floats(t.u)) for t in tubes]                      # not floats
        assert exact_tube_violations(g, exact) == [exact_tube_violation(p, t) for p, t in zip(g, exact)]
    mixed = groups[0][:2] + groups[-1][:2]
    tubes = _tubes(mixed, rng, scale)
    assert exact_tube_violations(mixed, tubes) == [exact_tube_violation(p, t) for p, t in zip(mixed, tubes)]


def test_row_max_batch_is_exact_with_ties_and_extreme_values():
    rng = np.random.default_rng(3)
    big = 1 << 1100                                   # beyond float range: compared exactly
    for trial in range(200):
        K, R = 4, int(rng.integers(1, 6))
        num = rng.integers(-5, 6, size=(K, 3, R)).astype(object)
        if trial % 3 == 0:
            num[0, 0, 0] = big * int(rng.integers(-1, 2))
        if trial % 5 == 0:
            num[1, :, :] = 7                          # ties everywhere
        scale = np.array([int(x) for x in rng.integers(1, 4, size=R)], dtype=object)
        den = int(rng.integers(1, 9)) * (big if trial % 7 == 0 else 1)
        q = QArray(num, den)
        got = row_max_batch([(q, scale)])
        if trial % 3 and trial % 7:                   # row_max's float keys overflow on huge values
            assert got == [row_max(q[k], scale) for k in range(K)]
        assert got == [max(Fraction(int(num[k].ravel()[i]), int(scale[i % R]) * den) for i in range(3 * R))
                       for k in range(K)]


def test_row_max_batch_compares_families_with_other_denominators_exactly():
    """Rows of several families (denominators 3, 7 and 2**60) tie and nearly tie: each k's maximum
    is the exact one, whichever family holds it."""
    rng = np.random.default_rng(5)
    for trial in range(100):
        K = int(rng.integers(1, 5))
        fams, exact = [], [[] for _ in range(K)]
        for den in (3, 7, 1 << 60):
            R = int(rng.integers(1, 4))
            num = rng.integers(-4, 5, size=(K, R)).astype(object) * (den // 3 if den > 7 else 1)
            scale = np.array([int(x) for x in rng.integers(1, 3, size=R)], dtype=object)
            fams.append((QArray(num, den), scale))
            for k in range(K):
                exact[k] += [Fraction(int(num[k, r]), int(scale[r]) * den) for r in range(R)]
        assert row_max_batch(fams) == [max(e) for e in exact]


def test_settled_translates_keep_an_exact_copy_only_where_the_rounding_differs():
    """:func:`_settled_many` (one pass for a class) gives each translate's rounding and keeps its exact
    tube exactly where that rounding is not the tube itself (what ``settle`` decides one by one)."""
    rng = np.random.default_rng(11)
    L, n, nv, m = 3, 2, 4, 2
    for trial in range(30):
        third = Fraction(1, 3) if trial % 3 == 0 else Fraction(0)          # some tubes are not floats
        base = ExactTube(QArray.from_floats(rng.normal(size=(L, n))) + QArray.from_fractions([third]),
                         QArray.from_floats(rng.uniform(0.1, 1.0, size=L)),
                         QArray.from_floats(rng.normal(size=(L, nv, m))))
        shifts = np.round(rng.normal(size=(5, n)), int(rng.integers(0, 3))) * (trial % 2)
        moved = _translated_many(base, shifts)
        for t, s, (ev, ex) in zip(moved, shifts, _settled_many(moved)):
            ref = ExactTube(base.p + QArray.from_floats(s)[None, :], base.eps, base.u)
            assert np.array_equal(t.p.to_fractions(), ref.p.to_fractions())
            rounded = ref.to_float()
            assert all(np.array_equal(a, b) for a, b in zip(ev, rounded))
            same = all(np.array_equal(QArray.from_floats(a).to_fractions(), q.to_fractions())
                       for a, q in zip(rounded, ref))
            assert (ex is None) == same
            assert ex is None or all(np.array_equal(a.to_fractions(), b.to_fractions()) for a, b in zip(ex, ref))


def _same_verdicts(got, ref):
    for a, b in zip(got, ref):
        assert a.status == b.status
        assert abs(a.margin - b.margin) <= 1e-9 or (np.isnan(a.margin) and np.isnan(b.margin))
        if a.status == "edge":
            assert a.proof.level == b.proof.level == "exact"


def test_group_verdicts_equal_one_by_one_verdicts(groups):
    for g in groups:
        got = highs_translate_verdicts(g, "t")
        _same_verdicts(got, [highs_verdict(p, "t") for p in g])
        for p, v in zip(g, got):
            if v.status == "edge":
                assert tube_violation(p, v.tube) <= 1e-9 and exact_tube_violation(p, v.tube) <= 0 \
                    or v.proof.exact is not None and exact_tube_violation(p, v.proof.exact) <= 0


def test_zero_margin_translates_are_proved_by_a_translated_tube(groups):
    """At a zero margin (a tight tube) every translate after the first one proved takes that proof,
    moved by the exact offset; the exact check against its own data still decides."""
    tight = [g for g in groups if abs(highs_verdict(g[0]).margin) <= WARM_COLD_BAND
             and highs_verdict(g[0]).status == "edge"]
    assert tight, "the map has zero-margin translates"
    for g in tight:
        got = highs_translate_verdicts(g)
        _same_verdicts(got, [highs_verdict(p) for p in g])
        assert sum("translated" in v.proof.note for v in got) >= len(got) - 1


def test_a_failing_batch_candidate_falls_back_to_the_full_proof(groups):
    """An exact_batch that lies (says every candidate fails) costs speed, never an edge or a proof."""
    g = groups[0]
    liar = lambda probs, cands: [Fraction(1)] * len(probs)           # noqa: E731
    got = confirm_translates_with_highs(g, TranslateChecks(build_tube_lp, tube_violation, exact_batch=liar), "x")
    _same_verdicts(got, [highs_verdict(p) for p in g])


def test_split_future_spreads_results_and_errors():
    whole = Future()
    parts = split_future(whole, 3)
    whole.set_result(["a", "b", "c"])
    assert [p.result() for p in parts] == ["a", "b", "c"]
    whole = Future()
    parts = split_future(whole, 2)
    whole.set_exception(RuntimeError("boom"))
    for p in parts:
        with pytest.raises(RuntimeError, match="boom"):
            p.result()
    whole = Future()
    parts = split_future(whole, 2)
    whole.set_result(["only one"])
    with pytest.raises(RuntimeError, match="expected a list of 2"):
        parts[0].result()


def test_direct_groups_are_chunked_and_unique():
    from tubejax.lp.batch.sign_mode import DIRECT_GROUP
    far = DIRECT_GROUP + 40
    gs = _direct_groups([list(range(DIRECT_GROUP + 3)), [5, far], 7, far + 1], grouped=True)
    assert gs == [list(range(DIRECT_GROUP)), list(range(DIRECT_GROUP, DIRECT_GROUP + 3)), [far], [far + 1]]
    assert _direct_groups([[1, 2], 3], grouped=False) == [[1], [2], [3]]


@pytest.mark.parametrize("highs_process", [False, True])
def test_abstraction_with_grouped_confirmations_equals_every_lp_by_highs(paper_system, highs_process):
    """The PDHG path confirms translates of likely edges in groups; its transition system equals
    every candidate LP decided by HiGHS on its own (no classes) and the one-by-one confirmations."""
    from tubejax.lp.batch.batch_solver import PdhgBatchSolver
    d = parse_grid_map(MAP)
    s = paper_system(0.2)
    kw = dict(L_max=7, progress=False)
    grouped = PdhgBatchSolver(highs_process=highs_process)
    single = PdhgBatchSolver(highs_process=highs_process)
    single.form = single.form._replace(translates=False)               # every translate confirmed on its own
    a = build_abstraction(d, s, solve_batch=grouped, **kw)
    b = build_abstraction(d, s, solve_batch=single, **kw)
    key = lambda ts: [(e.src, e.dst, e.L) for e in ts.edges]           # noqa: E731
    assert key(a) == key(b)
    assert_each_instance_on_its_own(a, d, s, cross_sections(d, "box", 1.0), 7)
    assert a.stats["provenance"].get("exact-translate", 0) > 10        # proved by exact translation
    assert all(e.proof == "exact" for e in a.edges)
    # without the formulation's grouped verdicts every translate is solved by HiGHS: the same system
    off = b
    assert key(off) == key(a) and "exact-translate" not in off.stats["provenance"]
    assert sum(off.stats["provenance"].values()) == sum(a.stats["provenance"].values())
    margins = {(e.src, e.dst): e.margin for e in off.edges}
    assert all(abs(e.margin - margins[(e.src, e.dst)]) <= 1e-9 for e in a.edges)


def test_the_pdhg_path_gives_the_same_system_bit_for_bit_under_any_memory_budget(paper_system):
    """Chunks of a round (a memory budget) change which translates share a HiGHS job and which pair
    represents a class (so the route, ``provenance``, may change); every HiGHS answer starts from
    the class's canonical problem, so margins, tubes and proofs stay the same, bit for bit."""
    from tubejax.lp.batch.batch_solver import PdhgBatchSolver
    d = parse_grid_map(MAP)
    s = paper_system(0.2)
    solver = PdhgBatchSolver(highs_process=False)
    a = build_abstraction(d, s, solve_batch=solver, L_max=10, progress=False)
    b = build_abstraction(d, s, solve_batch=solver, L_max=10, progress=False, memory_budget_mb=1)
    assert len(b.stats["rounds"]) > len(a.stats["rounds"])
    same = lambda e: (e.src, e.dst, e.L, e.margin, e.proof, e.violation)      # noqa: E731 (not the route)
    assert [same(e) for e in a.edges] == [same(e) for e in b.edges]
    for x, y in zip(a.tubes, b.tubes):
        assert all(np.array_equal(u, v) for u, v in zip(x, y))
    assert any(abs(e.margin) <= WARM_COLD_BAND for e in a.edges)      # zero margins were among them


def test_a_translated_proof_is_refused_for_a_member_moved_by_1e_12():
    """Zero-margin translates (three-column moves at L = 10 on an open 2 x 7 grid, margin exactly 0,
    tests/test_zero_margin_systems.py): the canonical problem's exact tube, translated, proves
    every member -- except one whose target cell was moved away by 1e-12, which is no exact
    translate: its proof is refused and its own (exact) decision says it is no edge."""
    d = parse_grid_map("\n".join(["......."] * 2))
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    probs = [pair_problem(d, s, make_z("box", d.cells[c]), c, c + 3, 10) for c in range(4)]   # row 0
    lo, hi = probs[2].target.bounding_box()
    moved = dataclasses.replace(probs[2], target=Polytope.box(lo + [1e-12, 0.0], hi + [1e-12, 0.0]))
    assert not np.array_equal(moved.target.vertices, probs[2].target.vertices)
    good = highs_translate_verdicts(probs, TRANSLATE_EDGE)
    assert [v.provenance for v in good] == [TRANSLATED_PROOF] * 4       # none is its own canonical problem
    assert all(v.status == "edge" and v.margin <= 1e-9 and v.proof.level == "exact" for v in good)
    for v, p in zip(good, probs):                       # each proof holds for its own problem, exactly
        tube = v.proof.exact if v.proof.exact is not None else v.tube
        assert exact_tube_violation(p, tube) <= 0
    out = highs_translate_verdicts(probs[:2] + [moved] + probs[3:], TRANSLATE_EDGE)
    assert [v.provenance for v in out] == [TRANSLATED_PROOF, TRANSLATED_PROOF, TRANSLATE_EDGE, TRANSLATED_PROOF]
    assert out[2].status != "edge"
    assert exact_tube_violation(moved, good[2].proof.exact if good[2].proof.exact is not None else good[2].tube) > 0
    assert [v.provenance for v in highs_translate_verdicts(probs, TRANSLATE_EDGE, translated=False)] == \
        [TRANSLATE_EDGE] * 4


def _fresh_exact_caches():
    from tubejax.lp.evidence.exact_problem import clear_caches
    from tubejax.lp.evidence.rows import _RATIONAL_ROWS
    clear_caches()
    _RATIONAL_ROWS.clear()


def test_rational_rows_are_the_problems_own_after_its_canonical_problem():
    """A canonical problem on a grid of thirds rounds its vertices: the same float normals
    (``rows_key``) but other exact facets. The rational rows a member gets must be derived from
    its own exact facets whatever was derived before (they were the canonical problem's, and a
    dual certificate of those rows refused an edge)."""
    from tubejax.lp.evidence.exact_problem import exact_tube_data
    from tubejax.lp.evidence.rows import rational_tube_lp
    from tubejax.lp.declarations.tube_lp import rows_key
    from tubejax.model.workspace import box_grid
    d = box_grid([0.0, 0.0], [1.0, 1.0], [3, 3])
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.02))
    p = pair_problems(d, s, cross_sections(d, "box", 1.0), Pairs([5], [6], d.obstacle_cases([5], [6])), 3)[0]
    canon, _ = canonical_problem(p)
    assert rows_key(canon) == rows_key(p)
    assert not np.array_equal(exact_tube_data(canon).safe.H, exact_tube_data(p).safe.H)
    _fresh_exact_caches()
    own = rational_tube_lp(p, build_tube_lp(p)).rows
    _fresh_exact_caches()
    rational_tube_lp(canon, build_tube_lp(canon))
    assert rational_tube_lp(p, build_tube_lp(p)).rows == own


def test_a_zero_margin_edge_is_found_whether_or_not_its_canonical_problem_came_first():
    """The double integrator on a 6x7x6x6 grid (thirds and sevenths): this pair is an edge at
    L = 6 with margin exactly 0 (its exact proof). Confirmed one by one or with translates, the
    verdict is the same in either order (before, the canonical problem's rational rows were
    reused and an exact "dual certificate" refused it)."""
    import yaml
    from pathlib import Path
    from tubejax.model.workspace import box_grid
    conf = Path(__file__).resolve().parents[2] / "conf"
    ws = yaml.safe_load((conf / "workspace" / "boxgrid4d.yaml").read_text())
    cfg = yaml.safe_load((conf / "system" / "double_integrator.yaml").read_text())
    d = box_grid(ws["lower"], ws["upper"], [6, 7, 6, 6], obstacles=[tuple(o) for o in ws["obstacles"]])
    s = LinearSystem(A=np.array(cfg["A"], float), B=np.array(cfg["B"], float), U=box_input_set(1.0, 2),
                     W=Ball(4, 0.02))
    src, dst = np.array([365]), np.array([641])
    p = pair_problems(d, s, cross_sections(d, "cell", 1.0), Pairs(src, dst, d.obstacle_cases(src, dst)), 6)[0]
    for first in ("translates", "one"):
        _fresh_exact_caches()
        got = {}
        for how in ((first, "one") if first == "translates" else (first, "translates")):
            v = highs_translate_verdicts([p], "highs")[0] if how == "translates" else highs_verdict(p, "highs")
            got[how] = v
        for v in got.values():
            assert v.status == "edge" and v.margin == 0.0 and v.proof.level == "exact"
            assert exact_tube_violation(p, v.proof.exact if v.proof.exact is not None else v.tube) <= 0
