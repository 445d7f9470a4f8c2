"""The exported controller (C99 through ctypes, and the NumPy-only module) drives safe closed loops.

The exports are compiled and loaded here, driven by adversarial disturbances (the ``w`` in ``W``
pushing toward the facet of the next tube set with the least slack), and every state is checked by
the library's float64 monitors (:mod:`tubejax.analyses.control.run_checks`,
:func:`tubejax.analyses.spec.monitor.monitor`) against the library's own check sets
(:func:`~tubejax.analyses.control.plan_controller`), not the export's.
"""

import ctypes
import importlib.util
import shutil
import subprocess
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from tubejax.analyses.control import control_step, plan_controller, plan_sequence, sample_polytope  # noqa: E402
from tubejax.analyses.control.export import Lasso, export_controller, plan_lasso  # noqa: E402
from tubejax.analyses.control.run_checks import _check_runs  # noqa: E402
from tubejax.analyses.spec import lasso_words_satisfy, plan_formula, plan_ltl, plan_patrol  # noqa: E402
from tubejax.analyses.spec.monitor import monitor, region_letters  # noqa: E402
from tubejax.errors import InputError  # noqa: E402

PAPER_MAP = Path(__file__).resolve().parents[2] / "conf" / "workspace" / "maps" / "paper.txt"
CC = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
needs_cc = pytest.mark.skipif(CC is None, reason="no C compiler (cc, gcc or clang) on PATH: the C export "
                              "cannot be compiled here")
IN_TUBE, ADVANCED, FINISHED, OUTSIDE = 0, 1, 2, -1


class CState(ctypes.Structure):
    _fields_ = [("pos", ctypes.c_int), ("l", ctypes.c_int), ("finished", ctypes.c_int), ("last", ctypes.c_int),
                ("rounds", ctypes.c_longlong)]


class CController:
    """The compiled export, through ctypes."""

    def __init__(self, directory: Path):
        lib = directory / "libtc.so"
        subprocess.run([CC, "-std=c99", "-O2", "-Wall", "-Wextra", "-pedantic", "-Werror", "-shared", "-fPIC",
                        str(directory / "tubejax_controller.c"), "-o", str(lib), "-lm"], check=True,
                       capture_output=True, text=True)
        self.lib = ctypes.CDLL(str(lib))
        dp, ip = ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_int)
        self.lib.tubejax_controller_step.argtypes = [ctypes.POINTER(CState), dp, dp]
        self.lib.tubejax_controller_step.restype = ctypes.c_int
        self.lib.tubejax_controller_step_many.argtypes = [ctypes.POINTER(CState), ctypes.c_int, dp, dp, ip]
        self.lib.tubejax_controller_locate.argtypes = [ctypes.POINTER(CState), dp]

    def locate(self, state, x):
        x = np.ascontiguousarray(x, np.float64)
        return self.lib.tubejax_controller_locate(ctypes.byref(state),
                                                  x.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))

    def init(self, count: int):
        states = (CState * count)()
        for s in states:
            self.lib.tubejax_controller_init(ctypes.byref(s))
        return states

    def step_many(self, states, X, U):
        X = np.ascontiguousarray(X, np.float64)
        status = np.zeros(len(X), np.int32)
        self.lib.tubejax_controller_step_many(states, len(X), X.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
                                              U.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
                                              status.ctypes.data_as(ctypes.POINTER(ctypes.c_int)))
        return status


def load_python_export(directory: Path, name: str):
    spec = importlib.util.spec_from_file_location(name, directory / "tubejax_controller.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def paper():
    from tubejax.abstraction import build_abstraction
    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set
    from tubejax.model.workspace.gridmap import load_grid_map
    d = load_grid_map(PAPER_MAP)
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    ts = build_abstraction(d, s, L_max=10, progress=False)
    plan = plan_sequence(ts, d.cells_with_label("1")[0], ["3", "4", "5", "6"])
    return ts, plan


@pytest.fixture(scope="module")
def paper_export(paper, tmp_path_factory):
    ts, plan = paper
    out = tmp_path_factory.mktemp("export")
    export_controller(ts, plan, out)
    return out


def adversarial_runs(ts, plan, step_many, states, runs: int, seed: int):
    """Closed loops driven by ``step_many``; returns ``X (runs, S+1, n)``, ``U (runs, S, m)``, the
    statuses ``(runs, S)`` and the statuses of one more call (the plan finished)."""
    ctrl = plan_controller(ts, plan, jnp.float64)
    H, h = np.asarray(ctrl.H), np.asarray(ctrl.h)
    A, B, r = ts.system.A, ts.system.B, ts.system.W.radius
    S, n, m = plan.cost, ts.system.n, ts.system.m
    X = np.zeros((runs, S + 1, n))
    X[:, 0] = np.asarray(sample_polytope(jax.random.PRNGKey(seed), ts.decomposition.cells[plan.cells[0]], runs))
    U = np.zeros((runs, S, m))
    status = np.zeros((runs, S), int)
    u = np.zeros((runs, m))
    for t in range(S):
        status[:, t] = step_many(states, X[:, t], u)
        U[:, t] = u
        xbar = X[:, t] @ A.T + u @ B.T
        a = H[t + 1][np.argmin(h[t + 1][None] - xbar @ H[t + 1].T, axis=1)]     # least slack, unit normal
        X[:, t + 1] = xbar + r * a / np.linalg.norm(a, axis=1, keepdims=True)
    last = step_many(states, X[:, S], np.full((runs, m), np.nan))
    viol = np.max(np.einsum("tfn,rtn->rtf", H, X) - h[None], axis=2)
    return X, U, status, last, viol


def assert_safe(ts, plan, X, U, status, last, viol):
    runs = len(X)
    flags = _check_runs(ts.decomposition, plan, X, viol, 1e-9)
    assert int(flags["obstacle_entry"].sum()) == 0
    assert int(flags["tube_exit"].sum()) == 0
    assert bool(flags["targets_reached"].all())
    assert not flags["workspace_exit"].any()
    assert np.all(status >= 0), "a state inside its tube got OUTSIDE"
    ends = np.cumsum(plan.steps) - 1
    assert np.all(status[:, ends] == ADVANCED) and np.all(np.delete(status, ends, axis=1) == IN_TUBE)
    assert np.all(last == FINISHED)
    assert np.max(U.reshape(-1, U.shape[-1]) @ ts.system.U.H.T - ts.system.U.h) <= 1e-9
    assert X.shape[0] == runs


def _run_paper_c(paper, paper_export, runs, seed):
    ts, plan = paper
    c = CController(paper_export)
    states = c.init(runs)
    return c, adversarial_runs(ts, plan, c.step_many, states, runs, seed)


@needs_cc
def test_c_export_adversarial_runs_are_safe_and_match_python(paper, paper_export):
    ts, plan = paper
    _, (X, U, status, last, viol) = _run_paper_c(paper, paper_export, 1000, seed=1)
    assert_safe(ts, plan, X, U, status, last, viol)
    # the NumPy export, run along the same states: the same inputs to 1e-12 (10 runs, every step)
    tc = load_python_export(paper_export, "tc_paper")
    for r in range(10):
        st, u = tc.init(), np.zeros(2)
        for t in range(plan.cost):
            assert tc.step(st, X[r, t], u) == status[r, t]
            assert np.max(np.abs(u - U[r, t])) <= 1e-12
        assert tc.step(st, X[r, -1], u) == FINISHED
    # the library's controller (JAX) on the same states agrees to rounding
    ctrl = plan_controller(ts, plan, jnp.float64)
    lib = jax.vmap(jax.vmap(control_step), in_axes=(0, None, None, None, None, None))(
        jnp.asarray(X[:50, :-1]), ctrl.T, ctrl.r, ctrl.simplices, ctrl.valid, ctrl.u)[0]
    assert np.max(np.abs(np.asarray(lib) - U[:50])) <= 1e-12


@pytest.mark.slow
@needs_cc
def test_c_export_10000_adversarial_runs(paper, paper_export):
    """The issue's figures: 10,000 runs through the C export, 10,000 states compared with the NumPy export."""
    ts, plan = paper
    _, (X, U, status, last, viol) = _run_paper_c(paper, paper_export, 10_000, seed=2)
    assert_safe(ts, plan, X, U, status, last, viol)
    tc = load_python_export(paper_export, "tc_paper_slow")
    runs = -(-10_000 // plan.cost)
    worst = 0.0
    for r in range(runs):
        st, u = tc.init(), np.zeros(2)
        for t in range(plan.cost):
            assert tc.step(st, X[r, t], u) == status[r, t]
            worst = max(worst, float(np.max(np.abs(u - U[r, t]))))
    assert runs * plan.cost >= 10_000 and worst <= 1e-12


@needs_cc
def test_state_outside_every_tube_gets_the_status_and_no_input(paper, paper_export):
    ts, plan = paper
    c = CController(paper_export)
    tc = load_python_export(paper_export, "tc_outside")
    obstacle_point = np.array([1e3, -1e3])
    for x in (obstacle_point, np.array([np.nan, 0.0]), np.array([np.inf, 0.0])):
        s = c.init(1)
        u = np.full((1, 2), 123.0)
        assert c.step_many(s, x[None], u)[0] == OUTSIDE
        assert np.all(u == 123.0) and (s[0].pos, s[0].l, s[0].finished) == (0, 0, 0)
        st, up = tc.init(), np.full(2, 123.0)
        assert tc.step(st, x, up) == OUTSIDE and np.all(up == 123.0) and (st.pos, st.l) == (0, 0)
    # mid-run: a state pushed out of Q_l by a disturbance larger than W
    x0 = np.asarray(sample_polytope(jax.random.PRNGKey(0), ts.decomposition.cells[plan.cells[0]], 1))
    s = c.init(1)
    u = np.zeros((1, 2))
    assert c.step_many(s, x0, u)[0] == IN_TUBE
    x1 = x0 @ ts.system.A.T + u @ ts.system.B.T + np.array([[5.0, 5.0]])
    u_before = u.copy()
    assert c.step_many(s, x1, u)[0] == OUTSIDE and np.all(u == u_before) and s[0].l == 1


@needs_cc
def test_patrol_cycle_repeats(paper, tmp_path):
    """A patrol's cycle runs forever in the export: three rounds checked by the DFA monitor."""
    ts, _ = paper
    start = ts.decomposition.cells_with_label("1")[0]
    sp3 = plan_patrol(ts, start, ["3", "5"], cycles=3)
    lasso = plan_lasso(ts, plan_patrol(ts, start, ["3", "5"], cycles=1))
    assert lasso.repeats == -1 and lasso.cycle and ts.edges[lasso.cycle[-1]].dst == ts.edges[lasso.cycle[0]].src
    export_controller(ts, plan_patrol(ts, start, ["3", "5"], cycles=1), tmp_path, languages=("c",))
    c = CController(tmp_path)
    runs = 300
    states = c.init(runs)
    X, U, status, last, viol = adversarial_runs(ts, sp3.plan, c.step_many, states, runs, seed=3)
    flags = _check_runs(ts.decomposition, sp3.plan, X, viol, 1e-9)
    assert not flags["obstacle_entry"].any() and not flags["tube_exit"].any() and flags["targets_reached"].all()
    assert np.all(status >= 0) and np.all(last >= 0) and np.all(last != FINISHED)   # still patrolling
    assert all(s.rounds == 3 for s in states)
    assert monitor(sp3.dfa, ts.decomposition, X).satisfied.all()
    # a patrol exported for two rounds finishes after them
    export_controller(ts, sp3, tmp_path / "two", languages=("python",), cycles=2)
    tc = load_python_export(tmp_path / "two", "tc_two")
    st, u = tc.init(), np.zeros(2)
    n_two = sp3.stats["prefix_steps"] + 2 * sp3.stats["cycle_steps"]
    codes = [tc.step(st, X[0, t], u) for t in range(n_two)]
    assert min(codes) >= 0 and tc.step(st, X[0, n_two], u) == FINISHED


def test_python_export_alone_and_bad_input(paper, tmp_path):
    ts, plan = paper
    files = export_controller(ts, plan, tmp_path, languages="python")
    assert {f.name for f in files} == {"README.md", "tubejax_controller.json", "tubejax_controller.npz",
                                       "tubejax_controller.py"}
    text = (tmp_path / "tubejax_controller.py").read_text()
    imports = {line for line in text.splitlines() if line.startswith(("import ", "from "))}
    assert imports == {"from __future__ import annotations", "import json", "from pathlib import Path",
                       "import numpy as np"}
    readme = (tmp_path / "README.md").read_text()
    assert "radius 0.2" in readme and "OUTSIDE" in readme
    tc = load_python_export(tmp_path, "tc_alone")
    assert (tc.N, tc.M) == (2, 2) and tc.description()["plan"]["prefix_edges"] == [int(k) for k in plan.edges]
    x0 = ts.decomposition.cells[plan.cells[0]].vertices.mean(0)
    u = np.zeros(2)
    assert tc.step(tc.init(), x0, u) in (IN_TUBE, ADVANCED) and np.max(u @ ts.system.U.H.T - ts.system.U.h) <= 1e-12
    with pytest.raises(InputError, match="languages"):
        export_controller(ts, plan, tmp_path, languages=("rust",))
    with pytest.raises(InputError, match="cycles"):
        plan_lasso(ts, plan, cycles=0)
    e = ts.edges[plan.edges[0]]
    wrong = next(k for k, f in enumerate(ts.edges) if f.src != e.dst)
    with pytest.raises(InputError, match="leaves cell"):
        plan_lasso(ts, Lasso((plan.edges[0], wrong), (), 0, plan.cells[0]))
    with pytest.raises(InputError, match="repeats"):
        plan_lasso(ts, Lasso((), (plan.edges[0],), 0, plan.cells[0]))


@needs_cc
def test_empty_plan_finishes_at_once(paper, tmp_path):
    ts, _ = paper
    cell = ts.decomposition.cells_with_label("1")[0]
    export_controller(ts, Lasso((), (), 0, cell), tmp_path)
    tc = load_python_export(tmp_path, "tc_empty")
    c = ts.decomposition.cells[cell].vertices.mean(0)
    assert tc.step(tc.init(), c, np.zeros(2)) == FINISHED
    assert tc.step(tc.init(), c + 100.0, np.zeros(2)) == OUTSIDE
    cc = CController(tmp_path)
    u = np.full((2, 2), 7.0)
    assert list(cc.step_many(cc.init(2), np.stack([c, c + 100.0]), u)) == [FINISHED, OUTSIDE] and np.all(u == 7.0)


@needs_cc
def test_formula_plan_exports_and_satisfies_its_formula(paper, tmp_path):
    ts, _ = paper
    sp = plan_formula(ts, ts.decomposition.cells_with_label("1")[0], "F(l3 & F l6) & G(!l4)")
    export_controller(ts, sp, tmp_path, languages=("c",))
    c = CController(tmp_path)
    X, U, status, last, viol = adversarial_runs(ts, sp.plan, c.step_many, c.init(300), 300, seed=6)
    assert_safe(ts, sp.plan, X, U, status, last, viol)
    check = monitor(sp.dfa, ts.decomposition, X)
    assert check.satisfied.all() and not check.avoided_entry.any()


def _ltl_runs(ts, formula, out, languages, runs, seed, cycles=3):
    """An LTL lasso exported to run forever, driven for ``cycles`` turns; ``(sp, X, status, last, viol, step_many)``."""
    sp = plan_ltl(ts, ts.decomposition.cells_with_label("1")[0], formula, cycles=cycles)
    export_controller(ts, sp, out, languages=languages)
    if "c" in languages:
        c = CController(out)
        states, step_many = c.init(runs), c.step_many
    else:
        tc = load_python_export(out, f"tc_ltl_{seed}")
        states = [tc.init() for _ in range(runs)]

        def step_many(sts, X, U):
            return np.array([tc.step(st, x, u) for st, x, u in zip(sts, X, U)])
    X, U, status, last, viol = adversarial_runs(ts, sp.plan, step_many, states, runs, seed)
    return sp, X, U, status, last, viol


def _assert_ltl_runs(ts, sp, X, U, status, last, viol, cycles=3):
    flags = _check_runs(ts.decomposition, sp.plan, X, viol, 1e-9)
    assert not flags["obstacle_entry"].any() and not flags["tube_exit"].any() and not flags["workspace_exit"].any()
    assert np.all(status >= 0) and np.all(last >= 0) and np.all(last != FINISHED)      # the cycle goes on
    assert np.max(U.reshape(-1, U.shape[-1]) @ ts.system.U.H.T - ts.system.U.h) <= 1e-9
    # the run's float64 region word, checked by Spot against the formula (not the planner's product)
    props, labels = sp.dfa.propositions, sp.dfa.labels
    letters = region_letters(ts.decomposition, labels, X)
    P, C = sp.stats["prefix_steps"], sp.stats["cycle_steps"]
    assert lasso_words_satisfy(sp.spec, props, letters, P, C, cycles).all()
    # the check can fail: runs that never visit a region do not satisfy it
    assert not lasso_words_satisfy(sp.spec, props, np.zeros_like(letters), P, C, cycles).any()


def test_ltl_lasso_exports_and_its_runs_satisfy_the_formula_python(paper, tmp_path):
    """An LTL plan's lasso runs forever in the NumPy export; adversarial runs' words pass Spot's check."""
    ts, _ = paper
    sp, *rest = _ltl_runs(ts, "GF l3 & GF l5 & G !l4", tmp_path, ("python",), runs=40, seed=11)
    assert plan_lasso(ts, sp).repeats == -1 and plan_lasso(ts, sp, cycles=2).repeats == 2
    assert list(plan_lasso(ts, sp).cycle) == sp.lasso["cycle_edges"]
    _assert_ltl_runs(ts, sp, *rest)


@needs_cc
def test_ltl_lasso_exports_and_its_runs_satisfy_the_formula_c(paper, tmp_path):
    ts, _ = paper
    sp, *rest = _ltl_runs(ts, "GF l3 & GF l6 & G !l4", tmp_path, ("c",), runs=300, seed=12)
    _assert_ltl_runs(ts, sp, *rest)


def test_ltl_lasso_exported_for_some_turns_finishes(paper, tmp_path):
    ts, _ = paper
    sp = plan_ltl(ts, ts.decomposition.cells_with_label("1")[0], "GF l3 & GF l5", cycles=2)
    export_controller(ts, sp, tmp_path, languages=("python",), cycles=2)
    tc = load_python_export(tmp_path, "tc_ltl_two")
    X, U, status, last, viol = adversarial_runs(ts, sp.plan, lambda sts, X, U: np.array(
        [tc.step(st, x, u) for st, x, u in zip(sts, X, U)]), [tc.init() for _ in range(5)], 5, 13)
    assert np.all(status >= 0) and np.all(last == FINISHED)


@needs_cc
@pytest.mark.skipif(shutil.which("make") is None, reason="no make on PATH")
def test_makefile_builds_the_libraries(paper_export, tmp_path):
    for f in ("tubejax_controller.h", "tubejax_controller.c", "Makefile"):
        shutil.copy(paper_export / f, tmp_path / f)
    subprocess.run(["make", "-C", str(tmp_path), f"CC={CC}", "CFLAGS=-std=c99 -O2 -Wall -Wextra -pedantic -Werror"],
                   check=True, capture_output=True, text=True)
    assert (tmp_path / "libtubejax_controller.a").is_file() and (tmp_path / "libtubejax_controller.so").is_file()


@needs_cc
def test_multilinear_weights_on_box_sets(paper, tmp_path):
    """Multilinear weights (a box Z, box cells): safe adversarial runs, C = NumPy to 1e-12, weights on
    all 2^n corners that reproduce the point."""
    ts, plan = paper
    export_controller(ts, plan, tmp_path, weights="multilinear")
    with np.load(tmp_path / "tubejax_controller.npz") as z:
        assert z["set_box"].all()                        # every set of the paper map is a box
    c = CController(tmp_path)
    runs = 300
    X, U, status, last, viol = adversarial_runs(ts, plan, c.step_many, c.init(runs), runs, seed=4)
    assert_safe(ts, plan, X, U, status, last, viol)
    tc = load_python_export(tmp_path, "tc_multilinear")
    for r in range(5):
        st, u = tc.init(), np.zeros(2)
        for t in range(plan.cost):
            assert tc.step(st, X[r, t], u) == status[r, t]
            assert np.max(np.abs(u - U[r, t])) <= 1e-12
    # the weights themselves: all 2^n corners carry weight inside the box, and they reproduce the point
    ctl = tc.Controller(tmp_path)
    lo, hi = ctl.box[0]
    corners = np.where(ctl.bits, hi, lo)                 # corner c's coordinates
    y = lo + np.array([0.3, 0.8]) * (hi - lo)
    ids, w = ctl._weights(0, y, False)
    assert len(w) == 4 and np.all(w > 0) and abs(w.sum() - 1) <= 1e-15
    assert np.allclose(w @ corners, y, atol=1e-14) and sorted(ids) == [0, 1, 2, 3]
    with pytest.raises(InputError, match="weights"):
        export_controller(ts, plan, tmp_path, weights="nearest")


@pytest.fixture(scope="module")
def grid3d():
    import tubejax as tj
    ws = tj.box_grid([0, 0, 0], [3, 2, 1], [3, 2, 1], labels={"1": ([0, 0, 0], [1, 1, 1]), "2": ([2, 1, 0], [3, 2, 1])})
    s = tj.LinearSystem(A=np.eye(3), B=0.5 * np.eye(3), U=tj.box_input_set(1.0, 3), W=tj.Ball(3, 0.05))
    ts = tj.abstract(ws, s, solver="highs", L_max=6)
    return ts, plan_sequence(ts, ts.decomposition.cells_with_label("1")[0], ["2"])


@needs_cc
@pytest.mark.parametrize("weights", ["triangulation", "multilinear"])
def test_three_dimensional_box_grid(grid3d, tmp_path, weights):
    ts, plan = grid3d
    export_controller(ts, plan, tmp_path, weights=weights)
    c = CController(tmp_path)
    X, U, status, last, viol = adversarial_runs(ts, plan, c.step_many, c.init(200), 200, seed=5)
    assert_safe(ts, plan, X, U, status, last, viol)
    tc = load_python_export(tmp_path, f"tc_3d_{weights}")
    st, u = tc.init(), np.zeros(3)
    for t in range(plan.cost):
        assert tc.step(st, X[0, t], u) == status[0, t] and np.max(np.abs(u - U[0, t])) <= 1e-12



@needs_cc
def test_locate_resumes_the_plan_from_the_step_that_holds_the_state(paper, paper_export):
    """``locate`` after a lost state: the first step from here whose set holds it; the loop is safe from there."""
    ts, plan = paper
    c = CController(paper_export)
    tc = load_python_export(paper_export, "tc_locate")
    X, *_ = adversarial_runs(ts, plan, c.step_many, c.init(5), 5, seed=7)
    ctrl = plan_controller(ts, plan, jnp.float64)
    H, h = np.asarray(ctrl.H), np.asarray(ctrl.h)
    A, B, r = ts.system.A, ts.system.B, ts.system.W.radius
    starts = np.concatenate([[0], np.cumsum(plan.steps)])
    for run, t in [(0, 37), (1, 100), (2, 150), (3, plan.cost - 1)]:
        s = c.init(1)[0]
        assert c.locate(s, X[run, t]) == IN_TUBE
        st = tc.init()
        assert tc.locate(st, X[run, t]) == IN_TUBE and (st.pos, st.l) == (s.pos, s.l)
        t0 = int(starts[s.pos] + s.l)
        assert t0 <= t
        x, u = X[run, t].copy(), np.zeros((1, 2))
        for k in range(t0, plan.cost):                 # adversarial from the located step to the end
            status = c.lib.tubejax_controller_step(ctypes.byref(s), x.ctypes.data_as(ctypes.POINTER(ctypes.c_double)),
                                                   u.ctypes.data_as(ctypes.POINTER(ctypes.c_double)))
            assert status in (IN_TUBE, ADVANCED)
            xbar = A @ x + B @ u[0]
            a = H[k + 1][np.argmin(h[k + 1] - H[k + 1] @ xbar)]
            x = xbar + r * a / np.linalg.norm(a)
            assert np.max(H[k + 1] @ x - h[k + 1]) <= 1e-9
        assert c.locate(s, x) == FINISHED
    far = c.init(1)[0]
    assert c.locate(far, np.array([1e3, 1e3])) == OUTSIDE and (far.pos, far.l, far.rounds) == (0, 0, 0)


@needs_cc
def test_locate_wraps_around_a_patrol_cycle(paper, tmp_path):
    ts, _ = paper
    sp = plan_patrol(ts, ts.decomposition.cells_with_label("1")[0], ["3", "5"], cycles=2)
    export_controller(ts, sp, tmp_path)                          # the cycle repeats forever
    c = CController(tmp_path)
    tc = load_python_export(tmp_path, "tc_locate_patrol")
    n_pre = sp.plan.segment_ends[0]
    X, *_ = adversarial_runs(ts, sp.plan, c.step_many, c.init(2), 2, seed=8)
    cyc_start = int(sum(sp.plan.steps[:n_pre]))
    s = c.init(1)[0]
    s.pos, s.l = n_pre + 1, 0                                    # in the cycle's second transition
    st = tc.init()
    st.pos, st.l = n_pre + 1, 0
    x = X[0, cyc_start + 1]                                      # a state of the cycle's first transition
    assert c.locate(s, x) == IN_TUBE and tc.locate(st, x) == IN_TUBE
    assert (s.pos, s.l, s.rounds) == (st.pos, st.l, st.rounds)
    assert s.rounds == 1 and s.pos == n_pre
