"""Exact product decomposition (docs/math/product.md): detection, factor LPs, the join, verify.

The product path is compared with the joint tube LPs of today (``build_abstraction``: its edges must
be a subset, at the same or a larger ``L``) and with an independent HiGHS LP of the product family
over the full state (:func:`tubejax.verify.product_lp.product_lp_margin`).
"""

from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from omegaconf import OmegaConf

from tubejax.abstraction import build_abstraction
from tubejax.abstraction.product_abstraction import JOINT, ProductSystem, abstract_auto, build_product_abstraction
from tubejax.abstraction.product_joint_lps import merge_joint
from tubejax.abstraction.product_join import join_factors, lowest_bit
from tubejax.abstraction.product_transitions import product_transition_system
from tubejax.analyses.control.planner import _graph
from tubejax.transitions.records import Edge
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.product_structure import NotAProduct, axis_groups, product_structure
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set
from tubejax.model.workspace import box_grid
from tubejax.model.zshape.kinds import cross_sections
from tubejax.transitions.transition_system import TransitionSystem
from tubejax.verify.product_check import verify_product
from tubejax.verify.product_lp import ProductPair, product_lp_margin

CONF = Path(__file__).resolve().parents[1] / "conf"
L_MAX = 6


def di_problem(radius=0.05, A=None, B=None):
    cfg = OmegaConf.load(CONF / "system" / "double_integrator.yaml")
    ws = OmegaConf.load(CONF / "workspace" / "boxgrid4d.yaml")
    A = np.array(cfg.A, float) if A is None else A
    B = np.array(cfg.B, float) if B is None else B
    sysm = LinearSystem(A=A, B=B, U=box_input_set(1.0, 2), W=Ball(4, radius))
    d = box_grid(list(ws.lower), list(ws.upper), list(ws.divisions), obstacles=[tuple(o) for o in ws.obstacles])
    return d, sysm


@pytest.fixture(scope="module")
def di():
    d, sysm = di_problem()
    ps = build_product_abstraction(d, sysm, zshape="cell", L_max=L_MAX)
    ts = build_abstraction(d, sysm, zshape="cell", L_max=L_MAX, progress=False)
    return d, sysm, ps, ts


@pytest.fixture(scope="module")
def corner():
    """A 3x3 grid with an obstacle in a corner: the pair (0, 0) <-> (2, 2) has a blocked bounding box but a
    free hull, so it is solved as a joint LP with the paper's safe set."""
    d = box_grid([0, 0], [3, 3], [3, 3], obstacles=[([2, 0], [3, 1])])
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1))
    return d, sysm, build_product_abstraction(d, sysm, zshape="box", L_max=L_MAX)


# ----------------------------------------------------------------------------------------------- detection
def test_double_integrator_is_a_product_of_its_two_axes():
    d, sysm = di_problem()
    st = product_structure(d, sysm, cross_sections(d, "cell", 1.0))
    assert [list(f.axes) for f in st.factors] == [[0, 1], [2, 3]]
    assert [list(f.inputs) for f in st.factors] == [[0], [1]]
    for i, cell in enumerate(d.cells):            # every cell is the product of its factor cells
        lo, hi = cell.bounding_box()
        for g, f in enumerate(st.factors):
            flo, fhi = f.cells[st.cell_factor[i, g]].bounding_box()
            np.testing.assert_array_equal(flo, lo[list(f.axes)])
            np.testing.assert_array_equal(fhi, hi[list(f.axes)])
    np.testing.assert_array_equal(st.factors[1].system.A, sysm.A[2:, 2:])
    assert st.factors[0].system.W.radius == sysm.W.radius and st.factors[0].system.W.dim == 2


def test_a_rotated_double_integrator_is_coupled_and_runs_the_joint_lps():
    d, sysm = di_problem()
    c, s = np.cos(0.3), np.sin(0.3)
    R = np.kron(np.array([[c, -s], [s, c]]), np.eye(2))          # mixes the x and y axes
    rot = LinearSystem(A=R @ sysm.A @ R.T, B=R @ sysm.B, U=sysm.U, W=sysm.W)
    with pytest.raises(NotAProduct, match="couple all 4 state axes into one block"):
        product_structure(d, rot, cross_sections(d, "cell", 1.0))
    ts, why = abstract_auto(d, rot, zshape="cell", L_max=1)
    assert isinstance(ts, TransitionSystem) and "not a product" in why


def test_the_parts_that_couple_are_named():
    d, sysm = di_problem()
    Z = cross_sections(d, "cell", 1.0)
    with pytest.raises(NotAProduct, match="U is not the product"):
        product_structure(d, replace_U(sysm, one_norm_input_set(1.0, 2)), Z)
    X = {"H": [[0.0, 1.0, 0.0, 1.0]], "h": [3.0]}
    with pytest.raises(NotAProduct, match="row 0 of system.X involves the axes of groups"):
        product_structure(d, LinearSystem(A=sysm.A, B=sysm.B, U=sysm.U, W=sysm.W, X=X), Z)
    states, inputs = axis_groups(np.eye(3), np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]))
    assert states == [[0], [1], [2]] and inputs == [[0], [1], []]


def replace_U(sysm, U):
    return LinearSystem(A=sysm.A, B=sysm.B, U=U, W=sysm.W)


def test_a_state_constraint_on_one_group_is_split():
    d, sysm = di_problem()
    X = {"H": [[0.0, 0.0, -1.0, 1.0]], "h": [2.0]}               # s_y - p_y <= 2 (a speed limit on y)
    st = product_structure(d, LinearSystem(A=sysm.A, B=sysm.B, U=sysm.U, W=sysm.W, X=X),
                           cross_sections(d, "cell", 1.0))
    assert st.factors[0].system.X is None
    np.testing.assert_array_equal(st.factors[1].system.X.H, [[-1.0, 1.0]])


# ----------------------------------------------------------------------------------- the 4-D double integrator
def test_product_edges_contain_the_joint_edges_at_the_same_or_smaller_L(di):
    _, _, ps, ts = di
    pe = ps.edge_dict()
    je = {(e.src, e.dst): e.L for e in ts.edges}
    assert ts.n_edges > 0
    assert set(je) <= set(pe)
    assert all(pe[k] <= L for k, L in je.items())
    assert all(pe[k] == L for k, L in je.items())   # here every joint edge has its least L in the paper family too
    assert len(pe) > len(je)                          # one scale per group finds more


def test_product_edges_agree_with_an_independent_highs_lp_of_the_product_family(di):
    d, sysm, ps, _ = di
    groups = [f.axes for f in ps.structure.factors]
    lo, hi = d.cell_boxes()
    checked = 0
    for i, j, L, v in zip(ps.src.tolist(), ps.dst.tolist(), ps.L.tolist(), ps.variant.tolist()):
        safe = d.cells[i] if v == 1 else Polytope.box(np.minimum(lo[i], lo[j]), np.maximum(hi[i], hi[j]))
        assert product_lp_margin(sysm, ProductPair(d.cells[i], d.cells[j], safe, ps.Z[i]), groups, L) >= -1e-9
        if L > 1:
            assert product_lp_margin(sysm, ProductPair(d.cells[i], d.cells[j], safe, ps.Z[i]), groups, L - 1) < 0
        checked += 1
    assert checked == ps.n_edges


def test_the_join_does_not_depend_on_its_block_size(di):
    d, _, ps, _ = di
    one = join_factors(d, ps.structure, ps.tables, memory_mb=1e-9)     # one source cell per block
    all_ = join_factors(d, ps.structure, ps.tables, memory_mb=1e6)
    for a, b in ((one.src, all_.src), (one.dst, all_.dst), (one.L, all_.L), (one.margin, all_.margin)):
        np.testing.assert_array_equal(a, b)


def test_lowest_bit():
    m = np.array([0, 1, 2, 12, 1 << 40, (1 << 63) | 4], dtype=np.uint64)
    np.testing.assert_array_equal(lowest_bit(m), [-1, 0, 1, 2, 40, 2])


def test_every_edge_has_its_factor_proofs_and_a_product_tube(di):
    d, sysm, ps, _ = di
    for k in range(ps.n_edges):
        vs = ps.factor_verdicts(k)
        assert len(vs) == 2 and all(v.status == "edge" and v.tube is not None for v in vs)
        tube = ps.tube(k)
        i, j = int(ps.src[k]), int(ps.dst[k])
        q = tube.vertices(ps.Z[i], d.cells[i])
        assert q.shape == (int(ps.L[k]) + 1, 16, 4)
        assert np.all(d.cells[j].contains(q[-1], tol=1e-9))       # the last set lies in the target
        Z = ps.Z[i]
        g_of_row = tube.group_of_axis[np.argmax(Z.H != 0, axis=1)]
        for l in range(int(ps.L[k])):                               # C4 of the assembled tube, row by row
            x_next = q[l] @ sysm.A.T + tube.u[l] @ sysm.B.T
            lhs = (x_next - tube.p[l]) @ Z.H.T
            rhs = tube.eps[l, g_of_row] * Z.h - sysm.W.radius * np.linalg.norm(Z.H, axis=1)
            assert np.all(lhs <= rhs + 1e-9)
        assert np.all(np.abs(tube.u) <= 1 + 1e-12)


# ------------------------------------------------------------------------------------------------- verify
def test_verify_accepts_the_product_system(di):
    report = verify_product(di[2], complete=12, seed=3)
    assert report.ok, report.problems
    assert report.n_factor_checked > 0 and report.n_factor_exact == report.n_factor_checked
    assert report.n_edges_checked == di[2].n_edges and report.n_sampled == 12


def _tampered(ps: ProductSystem, **arrays) -> ProductSystem:
    return replace(ps, **{k: np.asarray(v) for k, v in arrays.items()})


def test_verify_catches_a_smaller_L_a_missing_edge_and_a_wrong_safe_set(di):
    ps = di[2]
    k = int(np.flatnonzero(ps.L > 1)[0])
    L = ps.L.copy()
    L[k] -= 1
    assert any("no edge verdict" in p or "least L" in p for p in verify_product(_tampered(ps, L=L)).problems)
    keep = np.arange(ps.n_edges) != k
    bad = _tampered(ps, src=ps.src[keep], dst=ps.dst[keep], L=ps.L[keep], margin=ps.margin[keep],
                    variant=ps.variant[keep])
    assert any("but not an edge" in p for p in verify_product(bad).problems)
    variant = ps.variant.copy()
    variant[k] = 1 - variant[k]
    assert any("bounding box" in p for p in verify_product(_tampered(ps, variant=variant)).problems)


def test_verify_catches_a_corrupted_factor_tube(di):
    ps = di[2]
    table = ps.tables[0]
    key = next(k for k in sorted(table.verdicts) if table.verdicts[k].status == "edge"
               and any(ps.factor_verdicts(e)[0] is table.verdicts[k] for e in range(ps.n_edges)))
    good = table.verdicts[key]
    tube = good.tube._replace(p=good.tube.p + 0.5)
    table.verdicts[key] = good._replace(tube=tube)
    try:
        problems = verify_product(ps, enumerate_join=False).problems
    finally:
        table.verdicts[key] = good
    assert any("violates the factor LP" in p for p in problems)


# ---------------------------------------------------------------------------------- a blocked bounding box
def test_a_blocked_box_with_a_free_hull_is_solved_as_a_joint_lp(corner):
    d, sysm, ps = corner
    ts = build_abstraction(d, sysm, zshape="box", L_max=L_MAX, progress=False)
    pe = ps.edge_dict()
    je = {(e.src, e.dst): e.L for e in ts.edges}
    assert set(je) <= set(pe) and all(pe[k] <= L for k, L in je.items())
    joint = {(int(i), int(j)) for i, j in zip(ps.src[ps.variant == JOINT], ps.dst[ps.variant == JOINT])}
    assert joint == {(0, 7), (7, 0)}                 # cells [0,1]^2 and [2,3]^2 around the obstacle's corner
    assert ps.stats["n_joint_pairs"] == 2
    report = verify_product(ps, complete=6)
    assert report.ok, report.problems


def test_factor_pruning_changes_nothing_but_the_lp_count(di, corner):
    for d, sysm, ps, zshape in ((di[0], di[1], di[2], "cell"), (corner[0], corner[1], corner[2], "box")):
        full = build_product_abstraction(d, sysm, zshape=zshape, L_max=L_MAX, pruning=False)
        assert full.edge_dict() == ps.edge_dict()
        assert ps.stats["n_factor_lps"] < full.stats["n_factor_lps"]
        for t_full, t in zip(full.tables, ps.tables):
            np.testing.assert_array_equal(t_full.feasible, t.feasible)


@pytest.mark.parametrize("zshape, why", [("diamond", "Z of cell 0 is not the product"),
                                         ("chamfer", "a chamfered Z is not a product")])
def test_a_cross_section_that_is_not_a_product_is_named(zshape, why):
    d = box_grid([0, 0], [3, 3], [3, 3])
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1))
    with pytest.raises(NotAProduct, match=why):
        product_structure(d, sysm, cross_sections(d, zshape, 1.0))


def test_merging_the_joint_edges_matches_a_dict_merge():
    """``merge_joint`` (binary search over sorted keys) against the plain dict merge it replaced."""
    rng = np.random.default_rng(5)
    N = 30
    pairs = {(int(i), int(j)) for i, j in rng.integers(0, N, size=(200, 2)) if i != j}
    src, dst = (np.array(x, dtype=np.int64) for x in zip(*sorted(pairs, key=lambda p: rng.random())))
    E = len(src)
    joined = SimpleNamespace(src=src, dst=dst, L=rng.integers(1, 7, E), margin=rng.random(E),
                             variant=rng.integers(0, 2, E))
    cand = [(int(i), int(j)) for i, j in rng.integers(0, N, size=(80, 2)) if i != j]
    jL = {p: int(rng.integers(1, 7)) for p in cand}
    jm = {p: float(rng.random()) for p in jL}
    want = {(i, j): (L, m, v) for i, j, L, m, v in zip(src.tolist(), dst.tolist(), joined.L.tolist(),
                                                      joined.margin.tolist(), joined.variant.tolist())}
    for p, Lj in jL.items():
        if p not in want or Lj < want[p][0]:
            want[p] = (Lj, jm[p], JOINT)
    got = {(i, j): (L, m, v) for i, j, L, m, v in zip(*(a.tolist() for a in merge_joint(joined, jL, jm, N)))}
    assert got == want and len(merge_joint(joined, jL, jm, N)[0]) == len(want)
    assert all(len(a) == E for a in merge_joint(joined, {}, {}, N))
    none = SimpleNamespace(src=src[:0], dst=dst[:0], L=joined.L[:0], margin=joined.margin[:0],
                           variant=joined.variant[:0])              # no joined edge: every joint edge is new
    got = list(zip(*(a.tolist() for a in merge_joint(none, jL, jm, N))))
    assert got == [(i, j, Lj, jm[(i, j)], JOINT) for (i, j), Lj in jL.items()]


def test_verify_catches_a_larger_L_an_edge_without_factor_proofs_and_a_joint_edge_without_its_lp(di):
    ps = di[2]
    k = int(np.flatnonzero(ps.L < L_MAX)[0])
    L = ps.L.copy()
    L[k] += 1
    problems = verify_product(_tampered(ps, L=L), exact=False).problems
    assert any(f"L={L[k]}, but the least L feasible in every group is {ps.L[k]}" in p for p in problems)
    have = set(ps.edge_dict())
    i, j = next((i, j) for i in range(ps.n_cells) for j in range(ps.n_cells) if i != j and (i, j) not in have)
    add = dict(src=np.append(ps.src, i), dst=np.append(ps.dst, j), L=np.append(ps.L, 1),
               margin=np.append(ps.margin, 0.1), variant=np.append(ps.variant, 0))
    problems = verify_product(_tampered(ps, **add), exact=False).problems
    assert any("no edge verdict" in p for p in problems) or any("bounding box" in p for p in problems)
    assert any(f"edge {i}->{j}: L=1, but the least L" in p for p in problems)
    variant = ps.variant.copy()
    variant[k] = JOINT
    problems = verify_product(_tampered(ps, variant=variant), exact=False).problems
    assert any("joint edge without a joint verdict" in p for p in problems)


def test_the_lazy_edges_are_the_edge_records_and_plan_like_a_list(di):
    ps = di[2]
    ts = product_transition_system(ps)
    want = [Edge(int(i), int(j), int(L), float(m), "product-joint" if v == JOINT else "product")
            for i, j, L, m, v in zip(ps.src, ps.dst, ps.L, ps.margin, ps.variant)]
    assert list(ts.edges) == want and [ts.edges[k] for k in range(len(want))] == want
    assert ts.edges[-1] == want[-1] and ts.edges[2:5] == want[2:5] and len(ts.edges) == ps.n_edges
    dup = want + [Edge(want[0].src, want[0].dst, want[0].L, 0.0, "product")]      # a tie: the first edge wins
    best = {}
    for k, e in enumerate(dup):
        if (e.src, e.dst) not in best or e.L < best[(e.src, e.dst)][0]:
            best[(e.src, e.dst)] = (e.L, k)
    for edges in (ts, TransitionSystem(ts.decomposition, ts.system, ts.Z, edges=dup)):
        pairs, cost, k = _graph(edges)
        got = {(int(i), int(j)): (int(c), int(kk)) for (i, j), c, kk in zip(pairs, cost, k)}
        assert got == best and list(map(tuple, pairs.tolist())) == sorted(best)
