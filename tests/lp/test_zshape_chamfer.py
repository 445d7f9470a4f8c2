"""The chamfered cross-section: a Z with twice the cell's vertices, paired with the cell's vertices and
edge midpoints. It closes the 1-norm corridor's gap to exact2d, and every edge goes through the same
evidence (HiGHS, float64, exact proof), files, verify and closed-loop control as any other."""

import os
import subprocess
import sys
from fractions import Fraction as F
from pathlib import Path

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.analyses.control import SimulationRuns, plan_controller, plan_sequence, simulate, simulate_edge
from tubejax.reachability.exact2d import exact_edges
from tubejax.model.geometry import Ball, Polytope
from tubejax.errors import InputModelError
from tubejax.inputs import ProblemInputs
from tubejax.lp.evidence.verdict import highs_solve_batch
from tubejax.model.zshape.kinds import CHAMFER_CUT, Z_GRID_BITS, make_z, source_points
from tubejax.lp.batch.batch_solver import PdhgBatchSolver
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set
from tubejax.transitions.transition_system import TransitionSystem
from tubejax.verify.verifier import verify_directory
from tubejax.model.workspace.gridmap import load_grid_map, parse_grid_map

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / "tests" / "data" / "tiny.txt"
L1 = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2), W=Ball(2, 0.2))
PAPER = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))


@pytest.fixture(scope="module")
def corridor_chamfer(corridor_path):
    decomp = load_grid_map(corridor_path)
    return decomp, build_abstraction(decomp, L1, zshape="chamfer", solve_batch=highs_solve_batch, progress=False)


def test_source_points_keep_the_cell():
    cell = Polytope.box([2.0, 3.0], [3.0, 4.0])
    assert source_points(cell, 4) is cell
    P = source_points(cell, 8)
    assert P is source_points(cell, 8)                                 # memoised
    assert P.vertices.tolist() == [[2, 3], [2.5, 3], [3, 3], [3, 3.5], [3, 4], [2.5, 4], [2, 4], [2, 3.5]]
    assert np.array_equal(Polytope.from_vertices(P.vertices).vertices, cell.vertices)    # the same hull
    assert np.array_equal(P.H, cell.H) and np.array_equal(P.h, cell.h)
    tri = Polytope.from_vertices([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    third = source_points(tri, 9).vertices
    assert third.shape == (9, 2) and np.allclose(third[1], [1 / 3, 0])
    with pytest.raises(ValueError, match="a multiple of it"):
        source_points(cell, 6)
    with pytest.raises(ValueError, match="a multiple of it"):
        source_points(Polytope.box([0.0] * 3, [1.0] * 3), 16)


def test_chamfer_z():
    cell = Polytope.box([0.0, 0.0], [1.0, 1.0])
    Z = make_z("chamfer", cell)
    assert Z.n_vertices == 8 and np.all(Z.h > 0)
    # the box scaled by a power of two (largest norm in (1/2, 1]) with each corner cut at CHAMFER_CUT
    # of its edges, on the dyadic grid of on_z_grid
    r = 0.5
    assert np.allclose(np.sort(np.abs(Z.vertices).ravel()), np.sort([r, r * (1 - 2 * CHAMFER_CUT)] * 8),
                       rtol=0, atol=2.0 ** -(Z_GRID_BITS + 1))
    assert np.array_equal(Z.vertices, np.round(Z.vertices * 2 ** Z_GRID_BITS) / 2 ** Z_GRID_BITS)
    prob = pair_problem(parse_grid_map(".."), PAPER, Z, 0, 1, 3)
    assert prob.source.n_vertices == 8 == prob.Z.n_vertices
    with pytest.raises(ValueError, match="2-D only"):
        make_z("chamfer", Polytope.box([0.0] * 3, [1.0] * 3))


def test_chamfer_closes_the_one_norm_corridor_gap(corridor_chamfer):
    decomp, ts = corridor_chamfer
    exact = exact_edges(decomp, L1, 10)
    box = build_abstraction(decomp, L1, zshape="box", solve_batch=highs_solve_batch, progress=False)
    assert box.n_edges == 44 and len(exact) == 70
    assert ts.n_edges >= 0.9 * len(exact)                                # the target; here: all 70
    for e in ts.edges:                                                  # sound: within exact2d
        assert (e.src, e.dst) in exact and e.L >= exact[(e.src, e.dst)][0]
    assert {(e.src, e.dst) for e in box.edges} <= {(e.src, e.dst) for e in ts.edges}
    assert np.all(ts.verify() <= 1e-9)
    assert {e.proof for e in ts.edges} == {"exact"}
    assert all(t.u.shape[1] == 8 for t in ts.tubes)                     # q_k(0): vertices and midpoints


def test_pdhg_gives_the_highs_system():
    decomp = parse_grid_map("#...\n....\n..#.")
    ref = build_abstraction(decomp, L1, zshape="chamfer", solve_batch=highs_solve_batch, L_max=6, progress=False)
    ts = build_abstraction(decomp, L1, zshape="chamfer", solve_batch=PdhgBatchSolver(), L_max=6, progress=False)
    assert ref.n_edges > 0
    assert {(e.src, e.dst, e.L) for e in ts.edges} == {(e.src, e.dst, e.L) for e in ref.edges}
    assert {e.proof for e in ts.edges} == {"exact"}


def test_files_verify_and_closed_loop(corridor_chamfer, tmp_path):
    decomp, ts = corridor_chamfer
    ts.save(tmp_path)
    back = TransitionSystem.load(tmp_path)
    assert back.n_edges == ts.n_edges and back.Z[0].n_vertices == 8
    assert np.all(back.verify() <= 1e-9)
    start = decomp.cells_with_label("1")[0]
    plan = plan_sequence(ts, start, ["2", "1"])
    for mode in ("adversarial", "boundary"):
        s = simulate(ts, plan, SimulationRuns(n_runs=100, mode=mode), ctrl=plan_controller(ts, plan)).summary()
        assert s["tube_exits"] == 0 and s["obstacle_entries"] == 0 and s["max_input_violation"] <= 1e-9
        assert s["runs_reaching_all_targets"] == 100
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tubejax.analyses.plot.figures import plot_tube
    fig, ax = plt.subplots()
    plot_tube(ts, 0, ax)                                                # q_k(0): 8 points, like Z
    plt.close(fig)
    two_cell = next(k for k, e in enumerate(ts.edges) if e.L == 10)   # a move the box cannot certify
    s = simulate_edge(ts, two_cell, SimulationRuns(n_runs=100, mode="adversarial", seed=1)).summary()
    assert s["tube_exits"] == 0 and s["max_tube_violation"] <= 1e-9 and s["runs_reaching_all_targets"] == 100


def test_the_app_runs_and_verify_rebuilds_it(tmp_path):
    out = tmp_path / "run"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    p = subprocess.run([sys.executable, str(ROOT / "experiments" / "abstract.py"), "progress=false", "zshape=chamfer",
                        "system=integrator2d_l1", "workspace=corridor", f"hydra.run.dir={out}"],
                       cwd=ROOT, capture_output=True, text=True, timeout=600, env=env)
    assert p.returncode == 0, p.stderr
    report = verify_directory(out, complete=True)
    assert report.ok, report.findings
    assert report.n_edges == 70 == report.proof_counts["exact"]


def test_chamfer_is_for_tubes_only():
    decomp = parse_grid_map("...")
    with pytest.raises(ValueError, match="applies to method 'tube'"):
        build_abstraction(decomp, L1, zshape="chamfer", method="openloop", progress=False)
    base = {"workspace": {"kind": "grid", "map_file": str(TINY)},
            "system": {"name": "integrator2d", "A": [[1.0, 0.0], [0.0, 1.0]], "B": [[0.5, 0.0], [0.0, 0.5]],
                       "U": {"kind": "box", "bound": 1.0}},
            "disturbance": {"kind": "ball", "radius": 0.2}, "zshape": {"kind": "chamfer", "scale": 1.0}}
    assert ProblemInputs.from_dict(base).zshape.kind == "chamfer"
    with pytest.raises(InputModelError, match="zshape.kind"):
        ProblemInputs.from_dict({**base, "abstraction": {"method": "openloop"}})


def test_the_cell_vertices_are_among_the_points_bit_for_bit():
    cell = Polytope.box([0.1, 0.7], [1.3, 2.9])
    P = source_points(cell, 8).vertices
    # the proofs read the points as rationals: the hull of the points contains P_i because its
    # vertices are among them exactly; the edge points may be rounded (each only adds constraints)
    assert np.array_equal(P[::2], cell.vertices)
    mid = [(F(float(a)) + F(float(b))) / 2 for a, b in zip(cell.vertices[0], cell.vertices[1])]
    assert all(abs(F(float(x)) - m) <= F(1, 2 ** 50) for x, m in zip(P[1], mid))


def test_the_open_loop_radius_form_ignores_a_chamfer_z():
    from tubejax.abstraction import cross_sections
    from tubejax.analyses.radius_analysis.radius_table import RadiusTableOptions, solve_radius_table

    decomp = parse_grid_map("...\n.#.")
    kw = dict(options=RadiusTableOptions(form="openloop", L_max=4), solver="highs")
    a = solve_radius_table(decomp, L1, Z=cross_sections(decomp, "chamfer", 1.0), **kw)
    b = solve_radius_table(decomp, L1, Z=cross_sections(decomp, "cell", 1.0), **kw)
    np.testing.assert_array_equal(a.value, b.value)
    assert np.array_equal(a.src, b.src) and np.array_equal(a.L, b.L) and len(a.value) > 0
    t = solve_radius_table(decomp, L1, Z=cross_sections(decomp, "chamfer", 1.0), solver="highs",
                           options=RadiusTableOptions(form="tube", L_max=4))
    assert all(p.source.n_vertices == 8 for p in t.problems(np.arange(3)))
