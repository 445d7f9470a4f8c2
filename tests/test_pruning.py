"""Pruning drops only infeasible instances: every pruned (i, j, L) is checked with HiGHS."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tubejax.abstraction.candidates import all_pairs, build_candidates
from tubejax.model.geometry import Ball, Polytope
from tubejax.lp.evidence.verdict import highs_verdict
from tubejax.model.zshape.kinds import make_z
from tubejax.model.problem import pair_problem
from tubejax.abstraction.pruning import PRUNE_REASONS, separating_directions
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set
from tubejax.model.workspace import box_grid, parse_grid_map


def kept_set(cand):
    k, L = np.nonzero(cand.keep)
    return {(int(cand.src[a]), int(cand.dst[a]), int(b) + 1) for a, b in zip(k, L)}


def check_pruned_instances_infeasible(decomp, system, zshape, L_max):
    """Solve every (i, j, L) with HiGHS; a pruned one must not be an edge. Returns the counts."""
    cand = build_candidates(decomp, system, L_max)
    kept = kept_set(cand)
    N = decomp.n_cells
    assert sum(cand.pruned.values()) + len(kept) == N * (N - 1) * L_max      # one reason each
    src, dst = all_pairs(N)
    edges = pruned_edges = 0
    for i, j in zip(src.tolist(), dst.tolist()):
        Z = make_z(zshape, decomp.cells[i])
        for L in range(1, L_max + 1):
            v = highs_verdict(pair_problem(decomp, system, Z, i, j, L))
            edges += v.status == "edge"
            if (i, j, L) not in kept:
                assert v.status != "edge", (i, j, L, v.margin)
                pruned_edges += v.status == "edge"
    return edges, len(kept)


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 31 - 1))
def test_pruned_instances_are_infeasible_2d(seed):
    rng = np.random.default_rng(seed)
    grid = np.full((3, 3), ".")
    grid[tuple(rng.integers(0, 3, 2))] = "#"
    decomp = parse_grid_map("\n".join("".join(r) for r in grid))
    A = np.eye(2) + rng.uniform(-0.15, 0.15, (2, 2))
    B = 0.5 * np.eye(2) + rng.uniform(-0.2, 0.2, (2, 2))
    U = box_input_set(rng.uniform(0.5, 1.5), 2) if rng.random() < 0.5 else one_norm_input_set(rng.uniform(0.7, 1.5), 2)
    system = LinearSystem(A=A, B=B, U=U, W=Ball(2, rng.uniform(0.02, 0.25)))
    edges, kept = check_pruned_instances_infeasible(decomp, system, "box", 4)
    assert kept < 8 * 7 * 4


@settings(max_examples=3, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 31 - 1))
def test_pruned_instances_are_infeasible_3d(seed):
    rng = np.random.default_rng(seed)
    decomp = box_grid([0, 0, 0], [2, 2, 2], [2, 2, 2], obstacles=[([1, 1, 0], [2, 2, 1])])
    dt = rng.uniform(0.3, 0.7)
    A = np.array([[1 - dt / 2, dt / 2, 0], [-dt / 2, 1 + dt / 2, 0], [0, 0, 1.0]])
    B = np.array([[dt * dt / 2, 0], [dt * dt / 2 + 2 * dt, 0], [0, 0.5]])
    system = LinearSystem(A=A, B=B, U=box_input_set(1.0, 2), W=Ball(3, rng.uniform(0.005, 0.05)))
    edges, kept = check_pruned_instances_infeasible(decomp, system, "cell", 4)
    assert edges > 0


def test_pruning_finds_the_hand_derived_first_horizon():
    """A = I, B = I/2, U = [-1, 1]^2, W = {0}: a state moves at most 1/2 per axis and step. In a
    1 x 6 corridor, P_0 = [0, 1] x [0, 1] meets P_5 = [5, 6] x [0, 1] first at L = 8 (set level),
    but its vertices at x = 0 need 10 steps to reach x >= 5: the first horizon kept is 10."""
    decomp = parse_grid_map("......")
    system = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.0))
    cand = build_candidates(decomp, system, 12)
    k = np.flatnonzero((cand.src == 0) & (cand.dst == 5))
    assert k.size == 1
    assert int(np.argmax(cand.keep[k[0]])) + 1 == 10
    assert cand.keep[k[0], 9:].all()
    assert cand.pruned["vertex_unreachable"] > 0


def test_directions_are_closed_under_negation_and_hold_the_axes():
    decomp = box_grid([0, 0, 0, 0], [2, 2, 2, 2], [2, 2, 2, 2])
    A = np.kron(np.eye(2), np.array([[0.75, 0.25], [-0.25, 1.25]]))
    B = np.kron(np.eye(2), np.array([[0.125], [1.125]]))
    system = LinearSystem(A=A, B=B, U=box_input_set(1.0, 2), W=Ball(4, 0.02))
    D, all_facets = separating_directions(decomp, system, 8)
    h = len(D) // 2
    np.testing.assert_array_equal(D[h:], -D[:h])
    np.testing.assert_array_equal(D[:4], np.eye(4))
    np.testing.assert_allclose(np.linalg.norm(D, axis=1), 1.0)
    assert all_facets
    # normals of the input reach sets: orthogonal to three of the axes and generators A^t B e_k
    G = np.array([np.linalg.matrix_power(A, t) @ B[:, k] for t in range(8) for k in range(2)])
    assert any(np.sum(np.abs(D[:h] @ G.T) < 1e-9) >= 3 and np.sum(np.abs(d) > 1e-9) > 1 for d in D[:h])


def test_counts_add_up_and_reasons_are_known(paper_system):
    decomp = parse_grid_map("1..#...\n.#.#.#.\n.#...#2\n...#...\n")
    cand = build_candidates(decomp, paper_system(0.2), 10)
    N = decomp.n_cells
    assert set(cand.pruned) == set(PRUNE_REASONS)
    assert sum(cand.pruned.values()) + cand.n_instances == N * (N - 1) * 10
    assert np.all(np.diff(cand.src) >= 0) and np.all(cand.src != cand.dst)
    assert cand.keep.shape == (len(cand.src), 10) and cand.keep.any(axis=1).all()
    off = build_candidates(decomp, paper_system(0.2), 10, pruning=False)
    assert off.n_instances == N * (N - 1) * 10 and sum(off.pruned.values()) == 0
    np.testing.assert_array_equal(off.obstacle, [decomp.obstacle_case(i, j) for i, j in zip(off.src, off.dst)])


@pytest.mark.parametrize("radius", [0.55, 0.7])
def test_target_too_small_removes_every_pair(paper_system, radius):
    decomp = parse_grid_map("...\n...\n")
    cand = build_candidates(decomp, paper_system(radius), 3)
    assert cand.n_instances == 0 and cand.pruned["target_too_small"] == 6 * 5 * 3


def test_degenerate_shrunk_target_uses_the_sound_fallback():
    """W = [-1/2, 1/2]^2 in a unit cell: P_j ⊖ W is a single point (no interior)."""
    decomp = parse_grid_map("..\n")
    W = Polytope.box([-0.5, -0.5], [0.5, 0.5])
    system = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=W)
    cand = build_candidates(decomp, system, 3)
    assert cand.pruned["target_too_small"] == 0
    check_pruned_instances_infeasible(decomp, system, "box", 3)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2 ** 31 - 1), n=st.integers(1, 4), tol=st.sampled_from([0.0, 1e-6]))
def test_kd_tree_candidates_equal_brute_force_box_overlap(seed, n, tol):
    from tubejax.abstraction.candidates import candidate_pairs

    rng = np.random.default_rng(seed)
    N = int(rng.integers(1, 60))
    t_lo = rng.uniform(0, 10, (N, n))
    t_hi = t_lo + rng.uniform(0.01, 2, (N, n)) * (rng.random((N, 1)) < 0.9)      # some empty-width targets
    r_lo = rng.uniform(-2, 10, (N, n))
    r_hi = r_lo + rng.uniform(0, 6, (N, n))
    targets = np.flatnonzero(rng.random(N) < 0.8)
    src, dst = candidate_pairs(r_lo, r_hi, t_lo, t_hi, targets, tol)
    got = set(zip(src.tolist(), dst.tolist()))
    want = {(i, j) for i in range(N) for j in targets.tolist() if i != j
            and np.all(r_lo[i] <= t_hi[j] + tol) and np.all(t_lo[j] <= r_hi[i] + tol)}
    assert got == want
    assert list(zip(src.tolist(), dst.tolist())) == sorted(got)
