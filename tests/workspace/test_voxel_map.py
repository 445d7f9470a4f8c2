"""3-D voxel maps: the parser against hand-derived cells, its errors, and Algorithm 2 in 3-D against
an independent one-LP-at-a-time HiGHS run of Problem 2 (docs/math/tube-lp.md), written here
from the page with scipy's hulls and highspy, not with tubejax's LP code."""

from __future__ import annotations

from pathlib import Path

import highspy
import jax
import numpy as np
import pytest

import tubejax as tj
from scipy.spatial import ConvexHull

from tubejax.abstraction import build_abstraction
from tubejax.model.geometry import Ball
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace.generate import building
from tubejax.model.workspace.gridmap import GridMapError
from tubejax.model.workspace.voxelmap import is_voxel_map, load_map, parse_map, parse_voxel_map
from tubejax.model.zshape.kinds import make_z

jax.config.update("jax_enable_x64", True)

SMALL = """\
1..#
.#..
---

..#.
.##2
"""


def test_cells_labels_and_obstacles_by_hand():
    d = parse_voxel_map(SMALL, "small")
    assert d.n_cells == 11 and d.cells[0].dim == 3
    # layer 0 (bottom, z in [0, 1]), row 0 is the top row (y in [1, 2]); numbering row-major
    assert d.grid.tolist()[:3] == [[0, 0, 0], [0, 0, 1], [0, 0, 2]]
    lo, hi = d.cells[0].bounding_box()
    assert lo.tolist() == [0, 1, 0] and hi.tolist() == [1, 2, 1]
    lo, hi = d.cells[-1].bounding_box()                        # '2': layer 1, row 1, column 3
    assert lo.tolist() == [3, 0, 1] and hi.tolist() == [4, 1, 2]
    assert d.labels[0] == "1" and d.labels[-1] == "2" and sum(lb is not None for lb in d.labels) == 2
    # obstacles: one box per run of '#' in a row: (0,0,3), (0,1,1), (1,0,2), (1,1,1..2)
    boxes = sorted((tuple(o.bounding_box()[0]), tuple(o.bounding_box()[1])) for o in d.obstacles)
    assert boxes == [((1, 0, 0), (2, 1, 1)), ((1, 0, 1), (3, 1, 2)), ((2, 1, 1), (3, 2, 2)),
                     ((3, 1, 0), (4, 2, 1))]
    assert d.domain.bounding_box()[1].tolist() == [4, 2, 2]
    assert is_voxel_map(SMALL) and not is_voxel_map("..\n..\n")
    assert parse_map("..\n.#\n").cells[0].dim == 2                # no layers: a 2-D grid map


@pytest.mark.parametrize("text, where", [
    ("..\n..\n---\n...\n...\n", "line 4: ragged row"),
    ("..\n..\n---\n..\n", "line 4: layer 2 has 1 rows, expected 2"),
    ("..\n\n..\n---\n..\n..\n", "line 2: a blank line inside layer 1"),
    ("..\n..\n---\n.?\n..\n", "line 4, column 2: unknown character '[?]'"),
    ("..\n..\n---\n---\n..\n..\n", "layer 2 is empty"),
    ("..\n..\n---\n", "layer 2 is empty"),
    ("##\n##\n---\n##\n##\n", "no free voxel"),
])
def test_errors_name_the_line(text, where):
    with pytest.raises(GridMapError, match=where):
        parse_voxel_map(text, "m.txt")


def test_load_map_names_the_file(tmp_path):
    p = tmp_path / "building.txt"
    p.write_text(SMALL)
    assert load_map(p).n_cells == 11
    with pytest.raises(GridMapError, match="nothere.txt"):
        load_map(tmp_path / "nothere.txt")


# ------------------------------------------------------------------ the independent reference
def _hrep(V):
    """Unit facets ``(H, h)`` of ``co(V)`` by scipy (qhull), duplicates merged."""
    eq = ConvexHull(V).equations
    H, h = eq[:, :-1], -eq[:, -1]
    _, idx = np.unique(np.round(np.hstack([H, h[:, None]]), 9), axis=0, return_index=True)
    return H[np.sort(idx)], h[np.sort(idx)]


def _obstacle_case(Vi, Vj, obstacles) -> bool:
    """Whether ``co(P_i u P_j)`` meets an obstacle box's interior: ``max s`` over ``x = sum lam v``,
    ``lo + s <= x <= hi - s`` is positive (one small LP per obstacle)."""
    V = np.vstack([Vi, Vj])
    for o in obstacles:
        lo, hi = o.bounding_box()
        n, k = V.shape[1], V.shape[0]
        h = highspy.Highs()
        h.setOptionValue("output_flag", False)
        h.addVars(k + 1, np.r_[np.zeros(k), -np.inf], np.r_[np.ones(k), np.inf])
        h.changeColCost(k, -1.0)
        h.addRow(1.0, 1.0, k, np.arange(k, dtype=np.int32), np.ones(k))
        for d in range(n):                      # lo_d + s <= sum lam v_d <= hi_d - s
            h.addRow(lo[d], np.inf, k + 1, np.arange(k + 1, dtype=np.int32), np.r_[V[:, d], -1.0])
            h.addRow(-np.inf, hi[d], k + 1, np.arange(k + 1, dtype=np.int32), np.r_[V[:, d], 1.0])
        h.run()
        if h.getModelStatus() == highspy.HighsModelStatus.kOptimal and -h.getInfo().objective_function_value > 1e-9:
            return True
    return False


def _margin(A, B, u_bound, radius, Vi, S, T, Z, Zv, L) -> float:
    """The optimal margin of Problem 2 (C1-C5, every state row relaxed by ``t`` times its unit
    normal's length), built from docs/math/tube-lp.md: variables ``p_l, eps_l`` (l = 1..L),
    ``u_k(l)`` (l = 0..L-1), ``t``; ``Zv`` (n_v, n) the vertices of ``Z`` (any pairing with the
    source's: each step's rows involve one vertex only)."""
    n, m, nv = A.shape[0], B.shape[1], Vi.shape[0]
    Hz, hz = Z
    col_p = lambda ell: (ell - 1) * n                         # noqa: E731
    col_e = lambda ell: L * n + ell - 1                       # noqa: E731
    col_u = lambda ell, k: L * (n + 1) + (ell * nv + k) * m    # noqa: E731
    nx = L * (n + 1) + L * nv * m + 1
    rows, rhs = [], []
    for ell in range(1, L + 1):                   # C2 (l < L) and C3 (l = L), per vertex
        Hs, hs = S if ell < L else T
        for k in range(nv):
            for a, b in zip(Hs, hs):
                r = np.zeros(nx)
                r[col_p(ell):col_p(ell) + n] = a
                r[col_e(ell)] = a @ Zv[k]
                r[-1] = 1.0
                rows.append(r)
                rhs.append(b)
    sw = radius * np.linalg.norm(Hz, axis=1)
    for ell in range(L):                          # C4: H_z (A q + B u - p_{l+1}) - eps_{l+1} h_z <= -sigma_W
        for k in range(nv):
            for f in range(len(hz)):
                r = np.zeros(nx)
                a = Hz[f]
                const = 0.0
                if ell == 0:
                    const = a @ (A @ Vi[k])
                else:
                    r[col_p(ell):col_p(ell) + n] += a @ A
                    r[col_e(ell)] += a @ A @ Zv[k]
                r[col_u(ell, k):col_u(ell, k) + m] += a @ B
                r[col_p(ell + 1):col_p(ell + 1) + n] -= a
                r[col_e(ell + 1)] -= hz[f]
                r[-1] = 1.0
                rows.append(r)
                rhs.append(-sw[f] - const)
    G = np.array(rows)
    lb = np.full(nx, -np.inf)
    ub = np.full(nx, np.inf)
    lb[L * n:L * (n + 1)] = 0.0                               # C1, eps_min = 0
    lb[L * (n + 1):-1], ub[L * (n + 1):-1] = -u_bound, u_bound  # C5, a box U
    ub[-1] = 1.0
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.addVars(nx, lb, ub)
    h.changeColCost(nx - 1, -1.0)
    for r, b in zip(G, rhs):
        nz = np.flatnonzero(r)
        h.addRow(-np.inf, b, len(nz), nz.astype(np.int32), r[nz])
    h.run()
    assert h.getModelStatus() == highspy.HighsModelStatus.kOptimal
    return -h.getInfo().objective_function_value


def test_abstraction_in_3d_equals_one_lp_at_a_time_highs():
    text = "1..\n.#.\n...\n---\n.#.\n...\n..2\n"
    d = parse_voxel_map(text, "two floors")
    radius, L_max = 0.05, 3
    A, B = np.eye(3), 0.5 * np.eye(3)
    system = LinearSystem(A=A, B=B, U=box_input_set(1.0, 3), W=Ball(3, radius))
    ts = build_abstraction(d, system, zshape="box", L_max=L_max, progress=False)
    got = {(e.src, e.dst): e.L for e in ts.edges}
    want = {}
    for i in range(d.n_cells):
        Z = make_z("box", d.cells[i])
        Zh = _hrep(Z.vertices)
        Vi = d.cells[i].vertices
        for j in range(d.n_cells):
            if i == j:
                continue
            Vj = d.cells[j].vertices
            S = _hrep(Vi) if _obstacle_case(Vi, Vj, d.obstacles) else _hrep(np.vstack([Vi, Vj]))
            T = _hrep(Vj)
            for L in range(1, L_max + 1):
                if _margin(A, B, 1.0, radius, Vi, S, T, Zh, Z.vertices, L) >= -1e-9:
                    want[(i, j)] = L
                    break
    assert len(want) > 20 and got == want


def test_generated_building_is_connected_and_deterministic():

    text = building(2, 8, 10, seed=1)
    assert text == building(2, 8, 10, seed=1) and text != building(2, 8, 10, seed=2)
    d = parse_voxel_map(text)
    assert (Path(__file__).resolve().parents[2] / "conf/workspace/maps/building3d.txt").read_text() == text
    assert d.labels.count("1") == 1 and d.labels.count("2") == 1
    assert d.grid[d.labels.index("1")][0] == 0 and d.grid[d.labels.index("2")][0] == 4   # bottom, top layer
    # every free voxel is reachable from every other through shared faces (the stairwells join the storeys)
    index = {tuple(g): k for k, g in enumerate(d.grid.tolist())}
    seen, todo = {0}, [0]
    while todo:
        k, r, c = d.grid[todo.pop()]
        for dk, dr, dc in ((1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)):
            nb = index.get((k + dk, r + dr, c + dc))
            if nb is not None and nb not in seen:
                seen.add(nb)
                todo.append(nb)
    assert len(seen) == d.n_cells
    slab = [g for g in d.grid.tolist() if g[0] == 2]                     # the slab: only the stairwells
    assert 1 <= len(slab) <= 8


def test_plan_and_adversarial_runs_in_3d():
    """Algorithm 1 in 3-D through the API: the plan goes from region 1 on the bottom layer to region 2
    on the top one, and adversarial runs stay in their tubes."""
    ws = tj.grid_map("1..\n.#.\n...\n---\n.#.\n...\n..2\n")
    system = tj.LinearSystem(A=np.eye(3), B=0.5 * np.eye(3), U=tj.box_input_set(1.0, 3), W=tj.Ball(3, 0.05))
    ts = tj.abstract(ws, system, L_max=3)
    plan = tj.plan(ts, [1, 2])
    cells = plan.plan.cells
    assert ts.decomposition.grid[cells[0]][0] == 0 and ts.decomposition.grid[cells[-1]][0] == 1
    report = tj.simulate(ts, plan, runs=200, disturbance="adversarial", seed=3)
    assert report.ok, report.findings
    traj = report.result.trajectories
    assert traj.shape[-1] == 3 and np.all(traj[:, -1, 2] >= 1.0)        # every run ends upstairs
    assert report.summary["obstacle_entries"] == 0 and report.summary["runs_reaching_all_targets"] == 200
