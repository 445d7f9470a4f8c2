"""Configuration-constrained tubes: they contain the fixed-Z tubes, their tubes pass an independent
float64 check, and their edges are exact2d edges."""

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.reachability.exact2d import exact_edges
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set
from tubejax.model.workspace.gridmap import load_grid_map, parse_grid_map
from tubejax.lp.declarations.tube_lp import TubeLP
from tubejax.lp.evidence.registry import formulation_of
from tubejax.lp.evidence.verdict import highs_verdict
from tubejax.analyses.zshape.ccp import (CcpLP, CcpTube, box_normals, build_ccp_lp, ccp_abstraction, ccp_margin,
                                         ccp_vertex_maps, ccp_violation, octagon_normals)
from tubejax.model.zshape.params import ZFamily, z_facets

L1 = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2), W=Ball(2, 0.2))
PAPER = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))



def tube_as_ccp(prob, tube):
    """A ``Z``-tube as a CCP tube with ``Z``'s normals: ``y_l = H_Z p_l + eps_l h_Z``; the inputs of the
    vertices ``w_k(y_l) = p_l + eps_l z_k`` are the tube's, matched by position (2-D polygon ``Z``:
    facet ``k`` runs from ``z_k`` to ``z_{k+1}``, so ``w_k`` is ``z_k``). Returns ``(N, tube)``."""
    z = prob.Z.vertices
    N, h = z_facets(ZFamily("polygon", 2, len(z), len(z)), z, np)      # facet k: edge z_k -> z_{k+1}
    y = tube.p @ N.T + tube.eps[:, None] * h
    return N, CcpTube(y, tube.u[0], tube.u[1:])


def test_vertex_maps_and_errors():
    Wm, E = ccp_vertex_maps(box_normals())
    y = np.array([0.5, 2.0, 1.0, 1.5])                  # -y <= .5, x <= 2, y <= 1, -x <= 1.5
    w = np.einsum("kdf,f->kd", Wm, y)
    np.testing.assert_allclose(w, [[-1.5, -0.5], [2, -0.5], [2, 1], [-1.5, 1]])
    np.testing.assert_allclose(E @ y, [3.5, 1.5, 3.5, 1.5])
    with pytest.raises(ValueError, match="counter-clockwise"):
        ccp_vertex_maps(box_normals()[::-1])
    with pytest.raises(ValueError, match="unit"):
        ccp_vertex_maps(2 * box_normals())


def test_every_z_tube_is_a_ccp_tube(corridor_path):
    """Edges of fixed-Z runs, rewritten with Z's normals as CCP tubes, pass the CCP check."""
    decomp = load_grid_map(corridor_path)
    runs = [build_abstraction(decomp, L1, zshape="box", progress=False),
            build_abstraction(decomp, PAPER, zshape="diamond", progress=False)]
    assert runs[0].n_edges == 44 and runs[1].n_edges > 0
    for ts in runs:
        for k in range(0, ts.n_edges, 3):
            prob = ts.problem(k)
            N, tube = tube_as_ccp(prob, ts.tubes[k])
            assert ccp_violation(prob, N, tube) <= 1e-9
            t, _, _ = ccp_margin(prob, N)
            assert t >= -1e-9                           # the CCP LP finds it feasible too


def test_octagon_tubes_reach_what_fixed_shapes_cannot(corridor_path):
    decomp = load_grid_map(corridor_path)
    exact = exact_edges(decomp, L1, 10)
    for (i, j, L) in [(10, 0, 10), (10, 15, 6)]:        # exact2d: L = 10 and 6; box Z: none, 10
        assert exact[(i, j)][0] == L
        prob = pair_problem(decomp, L1, Polytope.box([-1, -1], [1, 1]), i, j, L)
        t_box, tube_box, _ = ccp_margin(prob, box_normals())
        t, tube, viol = ccp_margin(prob, octagon_normals())
        assert t_box < 0 < t and viol <= 1e-9
        y = tube.y.copy()
        y[-1] -= 0.05                                   # a smaller last set: the images miss it
        assert ccp_violation(prob, octagon_normals(), tube._replace(y=y)) > 1e-2


def test_ccp_edges_are_exact2d_edges():
    decomp = parse_grid_map("...\n.#.")
    exact = exact_edges(decomp, L1, 6)
    box = build_abstraction(decomp, L1, zshape="box", L_max=6, progress=False)
    for N in (box_normals(), octagon_normals()):
        found = ccp_abstraction(decomp, L1, N, L_max=6)
        assert len(found) >= box.n_edges
        for (i, j), (L, _) in found.items():
            assert (i, j) in exact and L >= exact[(i, j)][0]


def test_ccp_lp_and_check_come_from_one_declaration(corridor_path):
    """The LP's rows at a random point equal the families' residuals per unit normal, family by
    family by name, and its largest slack is what ccp_violation reports (the margin rows)."""
    from tubejax.analyses.zshape.ccp import CCP_FAMILIES, CcpVars, build_ccp_lp, ccp_terms

    decomp = load_grid_map(corridor_path)
    rng = np.random.default_rng(3)
    for N in (box_normals(), octagon_normals()):
        prob = pair_problem(decomp, L1, Polytope.box([-1, -1], [1, 1]), 10, 15, 4)
        lp = build_ccp_lp(prob, N)
        d = ccp_terms(prob, N)
        x = rng.standard_normal(lp.G.shape[1])
        L, F, nv, m = lp.index
        ny, nu0 = L * F, nv * m
        v = CcpVars(x[:ny].reshape(L, F), x[ny:ny + nu0].reshape(nv, m), x[ny + nu0:].reshape(L - 1, F, m))
        assert lp.layout.names == ("safe", "target", "dynamics_0", "dynamics")
        for f in CCP_FAMILIES:
            if f.lp_role(d, False) != "margin":
                continue
            sl = lp.layout.slice(f.name)
            want = np.ravel((f.lhs(d, v) - f.rhs(d)) / f.scale(d))
            np.testing.assert_allclose(lp.G[sl] @ x - lp.g[sl], want, rtol=0, atol=1e-12, err_msg=f.name)


def test_a_ccp_lp_is_no_registered_formulation():
    """The CCP LP is an analysis LP with its own type: the registry refuses it by name instead of taking
    it for the tube LP, whose fields it shares."""
    prob = pair_problem(parse_grid_map("...\n.#."), L1, Polytope.box([-1, -1], [1, 1]), 0, 2, 3)
    lp = build_ccp_lp(prob, box_normals())
    assert type(lp) is CcpLP and lp._fields == TubeLP._fields and type(lp._replace(t_max=2.0)) is CcpLP
    with pytest.raises(TypeError, match="CcpLP is the evidence or LP of no registered formulation"):
        formulation_of(lp)


def test_a_one_step_ccp_lp_builds_and_contains_the_z_tube():
    """At ``L = 1`` the inputs after ``l = 0`` have no entries; the LP still builds, and the tube LP's
    tube (HiGHS), rewritten with Z's normals, passes the CCP check and the CCP margin is no smaller."""
    fast = LinearSystem(A=np.eye(2), B=1.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.1))
    prob = pair_problem(parse_grid_map("1..\n.#.\n..2\n"), fast, Polytope.box([-.5, -.5], [.5, .5]), 0, 1, 1)
    v = highs_verdict(prob, form="tube")
    assert v.status == "edge"
    N, tube = tube_as_ccp(prob, v.tube)
    assert ccp_violation(prob, N, tube) <= 1e-9
    t, ccp_tube, viol = ccp_margin(prob, N)
    assert t > 0 and viol <= 1e-9 and ccp_tube.u.shape == (0, 4, 2)
