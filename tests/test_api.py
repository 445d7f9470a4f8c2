"""The Python API (``import tubejax as tj``): entry points, the method/solver pairing, inputs records
that ``python -m tubejax verify`` proves, reports that answer."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest

import tubejax as tj
from tubejax.abstraction import build_abstraction
from tubejax.errors import InputError
from tubejax.reachability.exact2d import exact2d_solve_batch
from tubejax.lp.evidence.verdict import highs_solve_batch
from tubejax.lp.evidence.verdict import highs_solver
from tubejax.lp.batch.batch_solver import pdhg_solver
from tubejax.lp.batch.batch_solver import PdhgBatchSolver
from tubejax.abstraction.methods import solver_method
from tubejax.model.workspace import load_grid_map

openloop_solve_batch = highs_solver("openloop")

jax.config.update("jax_enable_x64", True)

ROOT = Path(__file__).resolve().parents[1]
CORRIDOR = ROOT / "conf" / "workspace" / "maps" / "corridor.txt"
TINY = "1..\n.#.\n..2\n"


def _cli_verify(directory, *args):
    return subprocess.run([sys.executable, "-m", "tubejax", "verify", str(directory), "--quiet", *args],
                          cwd=ROOT, capture_output=True, text=True, timeout=600)


# ------------------------------------------------------------------ the method/solver pairing
@pytest.fixture(scope="module")
def corridor():
    return load_grid_map(CORRIDOR)


def test_openloop_default_solver_is_the_open_loop_lp(corridor, paper_system):
    """Issue 24: method='openloop' with the default solver returned the TUBE LP's 78 edges."""
    tube = build_abstraction(corridor, paper_system(0.2), progress=False)
    ol = build_abstraction(corridor, paper_system(0.2), method="openloop", progress=False)
    ref = build_abstraction(corridor, paper_system(0.2), method="openloop", solve_batch=openloop_solve_batch,
                            progress=False)
    assert tube.n_edges == 78
    assert ol.n_edges == ref.n_edges == 0
    assert ol.method == "openloop"


def test_exact2d_default_solver_is_the_polygon_computation(corridor, paper_system):
    ex = build_abstraction(corridor, paper_system(0.2), method="exact2d", progress=False)
    ref = build_abstraction(corridor, paper_system(0.2), method="exact2d", solve_batch=exact2d_solve_batch,
                            progress=False)
    assert [(e.src, e.dst, e.L) for e in ex.edges] == [(e.src, e.dst, e.L) for e in ref.edges]
    assert {e.provenance for e in ex.edges} == {"exact2d"}


@pytest.mark.parametrize("method, solver", [("openloop", highs_solve_batch), ("exact2d", highs_solve_batch),
                                            ("tube", openloop_solve_batch), ("tube", exact2d_solve_batch),
                                            ("exact2d", openloop_solve_batch)])
def test_a_solver_of_another_method_is_refused(corridor, paper_system, method, solver):
    with pytest.raises(InputError, match=f"solves the problems of method '{solver_method(solver)}', but method is "
                                         f"'{method}'"):
        build_abstraction(corridor, paper_system(0.2), method=method, solve_batch=solver, progress=False)


def test_batched_solvers_say_their_method(corridor, paper_system):
    tube, ol = PdhgBatchSolver(highs_process=False), pdhg_solver("openloop", highs_process=False)
    assert solver_method(tube) == "tube" and solver_method(ol) == "openloop"
    with pytest.raises(InputError, match="PdhgBatchSolver \\(form 'tube'\\)"):
        build_abstraction(corridor, paper_system(0.2), method="openloop", solve_batch=tube, progress=False)
    with pytest.raises(InputError, match="but method is 'tube'"):
        build_abstraction(corridor, paper_system(0.2), solve_batch=ol, progress=False)


def test_unknown_method_and_undeclared_solvers(corridor, paper_system):
    with pytest.raises(InputError, match="method: expected one of tube, openloop, exact2d, got 'tubes'"):
        build_abstraction(corridor, paper_system(0.2), method="tubes", progress=False)

    def wrapper(problems, progress=None):          # says nothing: the caller is trusted
        return openloop_solve_batch(problems, progress=progress)

    assert solver_method(wrapper) is None
    assert build_abstraction(corridor, paper_system(0.2), method="openloop", solve_batch=wrapper,
                             progress=False).n_edges == 0
    wrapper.method = "tube"                        # a declared method is checked
    with pytest.raises(InputError, match="wrapper solves the problems of method 'tube'"):
        build_abstraction(corridor, paper_system(0.2), method="openloop", solve_batch=wrapper, progress=False)


# ------------------------------------------------------------------ tj.abstract and its records
@pytest.fixture(scope="module")
def corridor_ts():
    return tj.abstract(tj.grid_map(str(CORRIDOR)), tj.paper_system(0.2), solver="highs")


def test_abstract_records_its_inputs(corridor_ts):
    ts = corridor_ts
    assert ts.n_edges == 78 and ts.method == "tube" and ts.stats["solver"] == "highs"
    rec = ts.inputs
    assert rec["workspace"]["map_file"]["resolved"] == str(CORRIDOR)
    assert rec["system"]["U"] == {"kind": "box", "bound": 1.0}
    assert rec["disturbance"] == {"kind": "ball", "radius": 0.2}
    assert rec["abstraction"]["method"] == "tube" and rec["abstraction"]["solver"] == {"name": "highs"}


@pytest.mark.parametrize("method, n_edges", [("openloop", 0), ("exact2d", 78)])
def test_abstract_uses_each_methods_own_solver(method, n_edges):
    ts = tj.abstract(CORRIDOR, tj.paper_system(0.2), method=method, solver=None if method == "exact2d" else "highs")
    assert ts.method == method and ts.n_edges == n_edges
    assert ts.inputs["abstraction"]["method"] == method


def test_abstract_defaults_to_batched_pdhg(tmp_path):
    ts = tj.abstract(tj.grid_map(TINY), tj.paper_system(0.1), L_max=4, solver_options={"highs_process": False})
    ref = tj.abstract(tj.grid_map(TINY), tj.paper_system(0.1), L_max=4, solver="highs")
    assert ts.stats["solver"] == "pdhg" and ts.inputs["abstraction"]["solver"]["name"] == "pdhg"
    assert {e.provenance for e in ts.edges} <= {"pdhg+highs", "highs-fallback", "highs-translate", "exact-translate",
                                                 "highs"}
    assert [(e.src, e.dst, e.L) for e in ts.edges] == [(e.src, e.dst, e.L) for e in ref.edges]
    ts.save(tmp_path / "run")
    p = _cli_verify(tmp_path / "run")
    assert p.returncode == 0, p.stdout + p.stderr


def test_a_saved_api_system_verifies_from_its_sources(corridor_ts, tmp_path):
    corridor_ts.save(tmp_path / "run")
    p = _cli_verify(tmp_path / "run", "--complete")
    assert p.returncode == 0, p.stdout + p.stderr
    assert "verify OK: edges proved; complete" in p.stdout and "  78 edges" in p.stdout and str(CORRIDOR) in p.stdout


def test_a_map_given_as_text_is_saved_with_the_system(tmp_path):
    ts = tj.abstract(tj.grid_map(TINY), tj.paper_system(0.1), L_max=6, solver="highs")
    name = ts.inputs["workspace"]["map_file"]["path"]
    assert name.startswith("map-") and name.endswith(".txt") and ts.decomposition.name == name[:-4]
    before = json.dumps(ts.inputs)
    assert tj.verify(ts).ok and json.dumps(ts.inputs) == before        # verified in memory, record unchanged
    ts.save(tmp_path / "run")
    assert ts.inputs["workspace"]["map_file"]["resolved"] == str((tmp_path / "run" / name).resolve())
    assert (tmp_path / "run" / name).read_text() == TINY
    moved = tmp_path / "elsewhere"
    shutil.move(tmp_path / "run", moved)                   # the copy beside the files is found
    p = _cli_verify(moved)
    assert p.returncode == 0, p.stdout + p.stderr
    assert tj.load(moved).n_edges == ts.n_edges
    (moved / name).write_text(TINY.replace("2", "."))     # a changed map is refused
    p = _cli_verify(moved)
    assert p.returncode == 1 and "changed since it was recorded" in p.stdout


def test_verify_answers(corridor_ts):
    rep = tj.verify(corridor_ts)
    assert rep.ok and rep.findings == [] and rep.n_edges == 78 and rep.proof_counts["exact"] == 78
    assert "against its sources" in rep.summary
    tampered = tj.TransitionSystem(**{k: getattr(corridor_ts, k) for k in
                                      ("decomposition", "system", "Z", "eps_min", "method", "stats", "inputs")},
                                   edges=list(corridor_ts.edges), tubes=list(corridor_ts.tubes))
    e = tampered.edges[0]
    tampered.edges[0] = type(e)(e.src, e.dst, e.L, e.margin + 0.05, e.provenance, e.proof, e.violation)
    bad = tj.verify(tampered)
    assert not bad.ok and any("margin" in f for f in bad.findings)
    assert all("/tmp" not in f for f in bad.findings)
    assert isinstance(corridor_ts.verify(), np.ndarray)     # the array answer stays for old callers


def test_verify_without_inputs_record_checks_self_consistency(corridor, paper_system):
    ts = build_abstraction(corridor, paper_system(0.2), L_max=3, progress=False)
    rep = tj.verify(ts)
    assert rep.ok and "self-consistency only" in rep.summary


def test_plan_and_simulate_answer(corridor_ts):
    p = tj.plan(corridor_ts, [1, 2])
    assert p.plan.cells[0] in corridor_ts.decomposition.cells_with_label("1")
    sim = tj.simulate(corridor_ts, p, runs=50, disturbance="adversarial", seed=3)
    assert sim.ok and sim.findings == [] and sim.summary["runs"] == 50
    assert sim.trajectories.shape[0] == 50 and sim.summary["runs_satisfying_spec"] == 50
    f = tj.plan(corridor_ts, "F(l2)", start="1")
    assert f.plan.cells[0] == p.plan.cells[0] and f.cost == p.cost
    assert tj.simulate(corridor_ts, f.plan, runs=5).ok         # a bare Plan too


def test_simulate_reports_violations(corridor_ts):
    p = tj.plan(corridor_ts, [1, 2])
    sim = tj.simulate(corridor_ts, p.plan, runs=20, disturbance="none")
    assert sim.ok
    # a larger disturbance than designed for is simulated through the library: the report must say so
    from tubejax.analyses.control import SimulationRuns, simulate as raw
    from tubejax.model.geometry import Ball
    res = raw(corridor_ts, p.plan, SimulationRuns(n_runs=50, mode="adversarial", W=Ball(2, 0.6)))
    assert res.summary()["tube_exits"] > 0
    from tubejax.analyses.control.simulate import summary_violations
    assert any("tube exits" in f for f in summary_violations(res.summary()))


@pytest.mark.parametrize("call, match", [
    (lambda ts: tj.plan(ts, [1, 7]), "label"),
    (lambda ts: tj.plan(ts, [1, 2], start=5), "does not carry the sequence's first label '1'"),
    (lambda ts: tj.plan(ts, [1, 2], start=99), r"start: expected a cell id in \[0, 20\]"),
    (lambda ts: tj.plan(ts, "F(l2)"), "a formula needs a start cell"),
    (lambda ts: tj.plan(ts, [1, 2], planner="fast"), "planner"),
    (lambda ts: tj.simulate(ts, tj.plan(ts, [1, 2]), runs=0), "runs"),
    (lambda ts: tj.simulate(ts, tj.plan(ts, [1, 2]), disturbance="gust"), "disturbance"),
    (lambda ts: tj.simulate(ts, [0, 2]), "plan: expected a plan from tj.plan"),
    (lambda ts: tj.verify(42), "target: expected a TransitionSystem or a directory"),
])
def test_bad_plan_simulate_verify_arguments(corridor_ts, call, match):
    with pytest.raises(ValueError, match=match):
        call(corridor_ts)


@pytest.mark.parametrize("kwargs, match", [
    ({"L_max": 0}, r"^L_max: expected an integer in \[1, 1000\], got 0"),
    ({"method": "exact2d", "solver": "highs"}, "method 'exact2d' solves no LP and takes no solver"),
    ({"method": "tubes"}, "^method: "),
    ({"solver": "gurobi"}, "^solver"),
    ({"solver_options": {"pool": 100}}, "^solver_options.pool: expected a power of two"),
    ({"solver": "highs", "solver_options": {"pool": 128}}, "^solver_options.pool"),
    ({"zshape": "star"}, "^zshape: "),
    ({"z_scale": 0.0}, "^z_scale: "),
    ({"min_margin": 0.9}, "^min_margin: "),
])
def test_bad_abstract_arguments_are_named(kwargs, match):
    with pytest.raises(InputError, match=match):
        tj.abstract(tj.grid_map(TINY), tj.paper_system(0.1), **kwargs)


def test_bad_workspaces_and_systems(corridor):
    with pytest.raises(InputError, match="a bare CellDecomposition has no source"):
        tj.abstract(corridor, tj.paper_system())
    with pytest.raises(InputError, match="expected a tubejax LinearSystem"):
        tj.abstract(tj.grid_map(TINY), {"A": [[1.0]]})
    with pytest.raises(InputError, match="not found"):
        tj.grid_map("no/such/map.txt")
    with pytest.raises(InputError, match="line 2, column 2: unknown character '\\?'"):
        tj.grid_map("1..\n.?.\n")
    with pytest.raises(InputError, match="u_set"):
        tj.paper_system(u_set="ball")
    with pytest.raises(InputError, match="radius"):
        tj.paper_system(-0.1)
    with pytest.raises(InputError, match="divisions"):
        tj.box_grid([0, 0], [1, 1], [2])


def test_systems_are_recorded_exactly():
    from tubejax.api_inputs import system_entries
    sysm, w = system_entries(tj.paper_system(0.2, u_set="one_norm"))
    assert sysm["U"] == {"kind": "one_norm", "radius": 1.0} and w == {"kind": "ball", "radius": 0.2}
    U = tj.Polytope.from_vertices(np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, -1.0]]))
    W = tj.Polytope.box([-0.1, -0.1], [0.1, 0.1])
    sysm, w = system_entries(tj.LinearSystem(A=np.eye(2), B=np.eye(2), U=U, W=W))
    assert sysm["U"]["kind"] == "polytope" and w == {"kind": "box", "half_width": 0.1}
    sysm, _ = system_entries(tj.LinearSystem(A=np.eye(2), B=np.eye(2), U=tj.box_input_set([1.0, 2.0]), W=W))
    assert sysm["U"] == {"kind": "box", "bound": [1.0, 2.0]}


def test_box_grid_and_polygon_workspaces(tmp_path):
    ws = tj.box_grid([0, 0], [3, 1], [3, 1], labels={"a": ([0, 0], [1, 1]), "b": ([2, 0], [3, 1])})
    assert ws.n_cells == 3 and ws.source["kind"] == "boxgrid"
    ts = tj.abstract(ws, tj.paper_system(0.05), L_max=4, solver="highs")
    ts.save(tmp_path / "grid")
    assert _cli_verify(tmp_path / "grid").returncode == 0
    poly = tj.polygon_workspace(ROOT / "conf" / "workspace" / "maps" / "rooms.yaml")
    assert poly.source["kind"] == "polygon" and poly.n_cells > 10
    text = (ROOT / "conf" / "workspace" / "maps" / "rooms.yaml").read_text()
    assert tj.polygon_workspace(text).n_cells == poly.n_cells


def test_package_namespace():
    assert tj.__version__ == "0.1.0" or tj.__version__[0].isdigit()
    import tubejax.verify.verifier                                  # the submodule must not shadow tj.verify
    from tubejax.verify.verifier import verify_directory            # noqa: F401
    assert callable(tj.verify) and tj.verify.__module__ == "tubejax.api"
    assert {"abstract", "plan", "simulate", "verify", "grid_map", "paper_system", "plot"} <= set(dir(tj))
    with pytest.raises(AttributeError):
        tj.no_such_name
    code = "import sys, tubejax.lp.engines.workers; print('jax' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.stdout.strip() == "False", out.stderr        # importing a submodule stays light


def test_export_from_the_api(corridor_ts, tmp_path):
    import networkx as nx
    path = corridor_ts.export(tmp_path / "g.graphml")
    G = nx.read_graphml(path, node_type=int)
    assert G.number_of_edges() == 78 and G.graph["method"] == "tube"
    data = json.loads(json.dumps(nx.node_link_data(corridor_ts.to_networkx(), edges="links")))
    assert len(data["links"]) == 78


def test_a_custom_system_round_trips(tmp_path):
    U = tj.Polytope.from_vertices(np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.5], [0.2, -1.0]]))
    W = tj.Polytope.from_vertices(np.array([[0.05, 0.0], [-0.05, 0.04], [0.0, -0.05]]))
    rot = np.array([[np.cos(0.1), -np.sin(0.1)], [np.sin(0.1), np.cos(0.1)]])
    system = tj.LinearSystem(A=rot, B=0.5 * np.eye(2), U=U, W=W)
    ts = tj.abstract(TINY, system, L_max=3, solver="highs")
    assert ts.inputs["system"]["U"]["kind"] == "polytope" and ts.inputs["disturbance"]["kind"] == "polytope"
    assert ts.system.A.tolist() == rot.tolist()
    ts.save(tmp_path / "run")
    p = _cli_verify(tmp_path / "run", "--complete")
    assert p.returncode == 0, p.stdout + p.stderr


def test_bad_box_grid_and_text_arguments():
    with pytest.raises(InputError, match="lower: expected numbers"):
        tj.box_grid(["a", 0], [1, 1], 2)
    with pytest.raises(InputError, match="upper"):
        tj.box_grid([0, 0], [0, 1], 2)
    with pytest.raises(InputError, match="map: expected a file path or the file's text"):
        tj.grid_map(42)
