"""The per-vertex LP rule (tubejax.abstraction.vertex_lp) drops only infeasible instances."""

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

import tubejax.abstraction.candidates as candidates_module
from tubejax.abstraction.candidates import build_candidates
from tubejax.model.geometry import Ball
from tubejax.lp.evidence.verdict import highs_verdict
from tubejax.model.zshape.kinds import make_z
from tubejax.lp.engines.highs import new_highs, pass_margin_lp
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set
from tubejax.abstraction.vertex_screen import dual_bound, vertex_margin_lp
from tubejax.model.workspace import box_grid, parse_grid_map

from reference_cases import CONF


def kept(cand):
    k, L = np.nonzero(cand.keep)
    return {(int(cand.src[a]), int(cand.dst[a]), int(b) + 1) for a, b in zip(k, L)}


def candidates_with_vertex_lp(decomp, system, L_max, on: bool):
    """:func:`build_candidates` with the vertex-LP rule on or off in any dimension (the library runs it in
    dimensions ``>= VERTEX_LP_MIN_DIM`` only; a comparison needs both)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(candidates_module, "VERTEX_LP_MIN_DIM", 0 if on else 10 ** 9)
        return build_candidates(decomp, system, L_max)


def double_integrator():
    cfg = yaml.safe_load((CONF / "system" / "double_integrator.yaml").read_text())
    return LinearSystem(A=np.array(cfg["A"], float), B=np.array(cfg["B"], float), U=box_input_set(cfg["U"]["bound"], 2),
                        W=Ball(4, 0.02))


def test_vertex_lp_drops_only_non_edges_in_4d():
    """Every instance the vertex LPs drop (and no other rule) is solved with HiGHS: none is an edge."""
    ws = yaml.safe_load((CONF / "workspace" / "boxgrid4d.yaml").read_text())
    decomp = box_grid(ws["lower"], ws["upper"], [3, 2, 3, 2], obstacles=[tuple(o) for o in ws["obstacles"]])
    system = double_integrator()
    on = candidates_with_vertex_lp(decomp, system, 6, on=True)
    off = candidates_with_vertex_lp(decomp, system, 6, on=False)
    dropped = kept(off) - kept(on)
    assert kept(on) <= kept(off)
    assert on.pruned["vertex_lp_infeasible"] == len(dropped) > 20
    assert on.stats["n_vertex_lps"] > 0 and off.pruned["vertex_lp_infeasible"] == 0
    for i, j, L in sorted(dropped):
        v = highs_verdict(pair_problem(decomp, system, make_z("cell", decomp.cells[i]), i, j, L))
        assert v.status != "edge", (i, j, L, v.margin)


def test_vertex_lp_takes_a_non_box_input_set_by_its_bounding_box():
    """A non-box ``U`` (the 1-norm ball of the double integrator's inputs): the vertex LPs run over
    ``box(U) ⊇ U``, a relaxation, and every instance they drop is a non-edge by HiGHS (with ``U``)."""
    ws = yaml.safe_load((CONF / "workspace" / "boxgrid4d.yaml").read_text())
    decomp = box_grid(ws["lower"], ws["upper"], [3, 2, 3, 2], obstacles=[tuple(o) for o in ws["obstacles"]])
    di = double_integrator()
    system = LinearSystem(A=di.A, B=di.B, U=one_norm_input_set(1.0, 2), W=di.W)
    assert not system.u_is_box
    on = candidates_with_vertex_lp(decomp, system, 6, on=True)
    off = candidates_with_vertex_lp(decomp, system, 6, on=False)
    dropped = kept(off) - kept(on)
    assert kept(on) <= kept(off)
    assert on.pruned["vertex_lp_infeasible"] == len(dropped) > 0 and on.stats["n_vertex_lps"] > 0
    for i, j, L in sorted(dropped):
        v = highs_verdict(pair_problem(decomp, system, make_z("cell", decomp.cells[i]), i, j, L))
        assert v.status != "edge", (i, j, L, v.margin)


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2 ** 31 - 1))
def test_vertex_lp_drops_only_non_edges_in_2d(seed):
    rng = np.random.default_rng(seed)
    grid = np.full((3, 4), ".")
    grid[tuple(rng.integers(0, 3, 2))] = "#"
    decomp = parse_grid_map("\n".join("".join(r) for r in grid))
    A = np.eye(2) + rng.uniform(-0.2, 0.2, (2, 2))
    system = LinearSystem(A=A, B=0.5 * np.eye(2), U=box_input_set(rng.uniform(0.5, 1.5), 2), W=Ball(2, rng.uniform(0.02, 0.2)))
    on = candidates_with_vertex_lp(decomp, system, 5, on=True)
    off = candidates_with_vertex_lp(decomp, system, 5, on=False)
    for i, j, L in sorted(kept(off) - kept(on)):
        v = highs_verdict(pair_problem(decomp, system, make_z("box", decomp.cells[i]), i, j, L))
        assert v.status != "edge", (i, j, L, v.margin)


@settings(max_examples=30, deadline=None, derandomize=True)
@given(st.integers(0, 10 ** 6))
def test_dual_bound_is_an_upper_bound_and_tight_at_highs_duals(seed):
    """Weak duality: every y >= 0 bounds max t from above; HiGHS's optimal duals attain t*."""
    rng = np.random.default_rng(seed)
    R, C = int(rng.integers(2, 12)), int(rng.integers(1, 6))
    G = rng.normal(size=(R, C))
    G /= np.linalg.norm(G, axis=1, keepdims=True)
    rhs = rng.normal(size=R)
    lo, hi = -rng.uniform(0.1, 2, C), rng.uniform(0.1, 2, C)
    h = new_highs()
    pass_margin_lp(h, vertex_margin_lp(G, rhs, lo, hi))
    h.run()
    t_star = h.getSolution().col_value[-1]
    y = -np.asarray(h.getSolution().row_dual)
    if t_star < 1.0 - 1e-9:                          # t <= 1 not active: the rows' duals certify t*
        assert dual_bound(G, rhs, lo, hi, y) == pytest.approx(t_star, abs=1e-7)
    for _ in range(5):
        assert dual_bound(G, rhs, lo, hi, rng.random(R)) >= t_star - 1e-12
    assert dual_bound(G, rhs, lo, hi, np.zeros(R)) == np.inf


def test_screening_in_helper_processes_gives_the_same_instances(monkeypatch):
    from tubejax.lp.engines.workers import ProcessWorkers
    from tubejax.abstraction import vertex_lp
    monkeypatch.setattr(vertex_lp, "_JOB_PAIRS", 16)                # several chunks on this small grid
    from tubejax.abstraction.pruning import reach_tables
    from tubejax.abstraction.vertex_lp import vertex_lp_keep
    ws = yaml.safe_load((CONF / "workspace" / "boxgrid4d.yaml").read_text())
    decomp = box_grid(ws["lower"], ws["upper"], [3, 2, 3, 2], obstacles=[tuple(o) for o in ws["obstacles"]])
    system = double_integrator()
    cand = candidates_with_vertex_lp(decomp, system, 6, on=False)
    T = reach_tables(decomp, system, 6)
    args = (decomp, system, T, cand.src, cand.dst, cand.obstacle, cand.keep)
    here = vertex_lp_keep(*args)
    pool = ProcessWorkers(helpers=2)
    there = vertex_lp_keep(*args, workers=pool)
    assert pool.stats["jobs"] >= 2                                  # the pairs went out in chunks
    np.testing.assert_array_equal(here[0], there[0])
    assert here[1:] == there[1:] and here[1] > 0


def test_reused_duals_drop_what_solving_drops_with_fewer_lps(monkeypatch):
    """A dual point that refuted one vertex LP, tried on the next LPs of the same rows, drops the
    same instances as solving each with HiGHS (and only non-edges: the 4-D test above runs with
    reuse on), with fewer LPs; so do the inputs of unrefuted LPs, which skip LPs that cannot refute."""
    from tubejax.abstraction import vertex_lp
    ws = yaml.safe_load((CONF / "workspace" / "boxgrid4d.yaml").read_text())
    decomp = box_grid(ws["lower"], ws["upper"], [3, 3, 3, 2], obstacles=[tuple(o) for o in ws["obstacles"]])
    system = double_integrator()
    reuse = candidates_with_vertex_lp(decomp, system, 6, on=True)
    monkeypatch.setattr(vertex_lp, "_CERTIFICATES", 0)
    solve = candidates_with_vertex_lp(decomp, system, 6, on=True)
    assert solve.stats["n_vertex_duals_reused"] == 0 < reuse.stats["n_vertex_duals_reused"]
    assert solve.stats["n_vertex_lps_witnessed"] == 0 < reuse.stats["n_vertex_lps_witnessed"]
    assert kept(reuse) == kept(solve) and reuse.pruned == solve.pruned
    assert reuse.stats["n_vertex_lps"] < solve.stats["n_vertex_lps"]


@settings(max_examples=20, deadline=None, derandomize=True)
@given(st.integers(0, 10 ** 6))
def test_dual_bounds_of_many_duals_and_sides_equal_one_at_a_time(seed):
    from tubejax.abstraction.vertex_screen import dual_bounds
    rng = np.random.default_rng(seed)
    R, C, K, V = (int(rng.integers(1, 8)) for _ in range(4))
    G, rhs = rng.normal(size=(R, C)), rng.normal(size=(R, V))
    lo, hi = -rng.uniform(0, 2, C), rng.uniform(0, 2, C)
    Y = rng.random((K, R)) * (rng.random((K, 1)) < 0.8)           # some all-zero rows: no bound
    b = dual_bounds(G, rhs, lo, hi, Y)
    assert b.shape == (K, V)
    for a in range(K):
        for v in range(V):
            y = Y[a] / Y[a].sum() if Y[a].sum() > 0 else None
            want = np.inf if y is None else y @ rhs[:, v] + np.maximum(-(G.T @ y) * lo, -(G.T @ y) * hi).sum()
            assert b[a, v] == pytest.approx(want, rel=1e-9, abs=1e-9) and b[a, v] >= want


def test_one_screen_per_translation_class_gives_the_same_candidates(monkeypatch):
    """The vertex LPs screen one pair per exact translation class: the kept instances equal
    screening every pair, with fewer LPs (a shear, which fixes the x axis, on a grid; the rule
    forced on)."""
    from tubejax.abstraction.translation_classes import TranslationClasses

    decomp = parse_grid_map("......\n.#....\n......\n....#.\n")
    system = LinearSystem(A=np.array([[1.0, 0.3], [0.0, 1.0]]), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    by_class = candidates_with_vertex_lp(decomp, system, 6, on=True)
    monkeypatch.setattr(TranslationClasses, "group", lambda self, src, *a, **k: np.arange(len(src)))
    each = candidates_with_vertex_lp(decomp, system, 6, on=True)
    assert kept(by_class) == kept(each) and by_class.pruned == each.pruned
    assert each.pruned["vertex_lp_infeasible"] > 0
    assert 0 < by_class.stats["n_vertex_lps"] < each.stats["n_vertex_lps"]


def test_pairs_screened_together_drop_what_each_pair_alone_drops(monkeypatch):
    """screen_pairs takes the pairs of one shape together (their right-hand sides and dual bounds
    at once): with many pairs of several shapes per chunk, the kept instances equal screening
    every pair in a chunk of its own (no dual, witness or row of one shape reaches another)."""
    from tubejax.abstraction import candidates, vertex_lp
    ws = yaml.safe_load((CONF / "workspace" / "boxgrid4d.yaml").read_text())
    decomp = box_grid(ws["lower"], ws["upper"], [3, 3, 3, 2], obstacles=[tuple(o) for o in ws["obstacles"]])
    system = double_integrator()
    monkeypatch.setattr(candidates, "_helpers", lambda: None)        # in this process (counted below)
    calls = []
    real = vertex_lp.screen_pairs
    monkeypatch.setattr(vertex_lp, "screen_pairs", lambda jobs, const: calls.append(jobs) or real(jobs, const))
    together = candidates_with_vertex_lp(decomp, system, 6, on=True)
    shapes = [len({vertex_lp._shape_key(j) for j in jobs}) for jobs in calls]
    assert max(shapes) >= 3 and max(map(len, calls)) >= 64          # chunks of several shapes
    monkeypatch.setattr(vertex_lp, "_JOB_PAIRS", 1)
    monkeypatch.setattr(vertex_lp, "_JOB_CHUNKS", 10 ** 9)
    calls.clear()
    alone = candidates_with_vertex_lp(decomp, system, 6, on=True)
    assert max(map(len, calls)) == 1
    assert kept(together) == kept(alone) and together.pruned == alone.pruned
    assert together.pruned["vertex_lp_infeasible"] > 0
    assert together.stats["n_vertex_duals_reused"] > alone.stats["n_vertex_duals_reused"]
