"""Vectorised closed-loop simulation of Algorithm 3 (docs/math/control.md).

The whole plan is one ``lax.scan`` over time (the edges' ``L`` steps
concatenated, see :func:`~tubejax.analyses.control.controller.plan_controller`),
``vmap``-ed over runs. Each run starts from a state uniform in the first cell
and draws its own disturbances:

``'uniform'``      uniform in ``W``;
``'boundary'``     uniform on the boundary of ``W``;
``'adversarial'``  the ``w in W`` pushing the state toward the nearest facet of the
                   next tube set: with ``xbar = A x + B u`` and ``a`` the unit
                   outward normal of the facet of ``Q_{l+1}`` with the least slack
                   at ``xbar``, ``w`` maximises ``a.w`` over ``W`` (``r a`` for a
                   ball, a maximising vertex for a polytope);
``'none'``         ``w = 0``.

Polytopes are sampled exactly (no rejection): pick a simplex of a fixed
triangulation with probability proportional to its volume, then a
Dirichlet(1, ..., 1) point in it (for the boundary: a triangulation of the
facets). Data-dependent failures are never exceptions inside ``jit``: they come
back as arrays (tube violations, barycentric "outside" amounts) and the host
turns them into per-run flags:

(a) obstacle entry: a state strictly inside an obstacle and in no cell (up to ``1e-9``);
(b) tube exit: a state outside its current tube set by more than ``tol``;
(c) target reached: the state at the end of each segment lies in a cell of
    the segment's label;
(d) state constraints: per constraint of ``system.state_constraints``, the states outside it
    by more than ``tol`` (:mod:`~tubejax.analyses.control.state_constraints`).

The rollout is one batch; the host checks, which take most of the time, run in
chunks of :data:`CHUNK_RUNS` runs, and an optional progress bar (total: the runs)
advances per chunk. Chunking never changes a result: each check is per state.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

from tqdm.auto import tqdm

import jax
import jax.numpy as jnp
import numpy as np
import shapely
from scipy.spatial import ConvexHull

from ...model.geometry import Ball, Polytope
from .controller import EdgeController, control_step, plan_controller, set_violation, triangulate
from .planner import Plan, plan_edge
from .state_constraints import count_outside_state_constraints

__all__ = ["SimulationResult", "simulate", "simulate_edge", "summary_violations", "rollout", "sample_polytope",
           "in_obstacle_interior", "in_cells", "trace_count", "MODES", "CHUNK_RUNS"]

MODES = ("uniform", "boundary", "adversarial", "none")
#: Runs whose states :func:`simulate` checks at a time (its progress bar advances per chunk).
CHUNK_RUNS = 1000
_TRACES = {"rollout": 0}


def trace_count() -> int:
    """How many times the jitted rollout has been traced (compiled) in this process."""
    return _TRACES["rollout"]


# ------------------------------------------------------------------ sampling data
def _simplex_weights(S):
    """``S (n_s, k, n)`` simplices -> log of their ``(k-1)``-volumes (up to a constant)."""
    E = S[:, 1:, :] - S[:, :1, :]                               # (n_s, k-1, n)
    G = E @ np.transpose(E, (0, 2, 1))
    vol = np.sqrt(np.maximum(np.linalg.det(G), 0.0)) if E.shape[1] else np.ones(len(S))
    with np.errstate(divide="ignore"):
        return np.log(vol)


def _polytope_interior(P: Polytope):
    """``(simplices (n_s, n+1, n), logw (n_s,))`` of a triangulation of ``P``."""
    tri = triangulate(P.vertices)
    S = P.vertices[tri.simplices]
    return S, _simplex_weights(S)


def _polytope_boundary(P: Polytope):
    """``(simplices (n_b, n, n), logw (n_b,))`` triangulating the boundary of ``P``."""
    V = P.vertices
    if P.dim == 1:
        return V[:, None, :], np.zeros(2)
    S = V[ConvexHull(V).simplices]
    return S, _simplex_weights(S)


def _w_data(W, n, dtype):
    """JAX arrays describing ``W`` for the disturbance modes."""
    if isinstance(W, Ball):
        if W.dim != n:
            raise ValueError(f"W is a ball in R^{W.dim}, the state is in R^{n}")
        z = jnp.zeros((1, 1, n), dtype)
        return dict(radius=jnp.asarray(W.radius, dtype), vertices=jnp.zeros((1, n), dtype),
                    S_in=z, w_in=jnp.zeros(1, dtype), S_bd=z, w_bd=jnp.zeros(1, dtype)), True
    if not isinstance(W, Polytope) or W.dim != n:
        raise ValueError(f"W must be a Ball or a Polytope in R^{n}, got {W!r}")
    S_in, w_in = _polytope_interior(W)
    S_bd, w_bd = _polytope_boundary(W)
    return dict(radius=jnp.asarray(0.0, dtype), vertices=jnp.asarray(W.vertices, dtype),
                S_in=jnp.asarray(S_in, dtype), w_in=jnp.asarray(w_in, dtype),
                S_bd=jnp.asarray(S_bd, dtype), w_bd=jnp.asarray(w_bd, dtype)), False


def _in_simplices(v, S, logw):
    """A point uniform in the union of simplices ``S (n_s, k, n)`` weighted by ``exp(logw)``.

    ``v`` holds ``k + 1`` numbers uniform in ``(0, 1)``: one picks the simplex
    (inverse CDF), the others give Dirichlet(1, ..., 1) weights via ``-log``.
    """
    k = S.shape[1]
    w = jnp.exp(logw - jnp.max(logw))
    cdf = jnp.cumsum(w) / jnp.sum(w)
    s = jnp.minimum(jnp.searchsorted(cdf, v[0]), S.shape[0] - 1)
    e = -jnp.log(v[1:k + 1])
    return (e / jnp.sum(e)) @ S[s]


def _uniform01(key, shape, dtype):
    """Uniform numbers in the open interval ``(0, 1)``."""
    tiny = 1e-15 if dtype == jnp.float64 else 1e-7
    return jnp.clip(jax.random.uniform(key, shape, dtype), tiny, 1.0 - tiny)


def sample_polytope(key, P: Polytope, num: int, dtype=None) -> jax.Array:
    """``num`` points uniform in ``P``, shape ``(num, n)`` (exact, via a triangulation).

    ``dtype`` defaults to float64 (computed with x64 enabled, whatever the global setting).
    """
    with jax.enable_x64(True):
        dtype = dtype or jnp.float64
        S, logw = _polytope_interior(P)
        return _sample_simplices(key, jnp.asarray(S, dtype), jnp.asarray(logw, dtype), int(num))


@partial(jax.jit, static_argnames=("num",))
def _sample_simplices(key, S, logw, num):
    v = _uniform01(key, (num, S.shape[1] + 1), S.dtype)
    return jax.vmap(lambda vi: _in_simplices(vi, S, logw))(v)


def _disturbance(v, wd, ball, mode_idx, Hn, hn, xbar):
    """``w`` for one step from ``v``, ``n + 2`` numbers uniform in ``(0, 1)``.

    ``mode_idx`` indexes :data:`MODES`; it is traced, so one compile serves all modes.
    """
    n = xbar.shape[0]

    def gauss():
        g = jax.scipy.special.ndtri(v[:n])
        return g / jnp.linalg.norm(g)

    def uniform(_):
        if ball:
            return wd["radius"] * v[n] ** (1.0 / n) * gauss()
        return _in_simplices(v, wd["S_in"], wd["w_in"])

    def boundary(_):
        if ball:
            return wd["radius"] * gauss()
        return _in_simplices(v, wd["S_bd"], wd["w_bd"])

    def adversarial(_):
        a = Hn[jnp.argmin(hn - Hn @ xbar)]       # unit outward normal, least slack
        if ball:
            return wd["radius"] * a / jnp.linalg.norm(a)
        return wd["vertices"][jnp.argmax(wd["vertices"] @ a)]

    def none(_):
        return jnp.zeros(n, xbar.dtype)

    return jax.lax.switch(mode_idx, [uniform, boundary, adversarial, none], None)


# ------------------------------------------------------------------ the JAX core
@partial(jax.jit, static_argnames=("ball",))
def _rollout(ctrl, A, B, x0, key, wd, mode_idx, ball):
    _TRACES["rollout"] += 1               # Python side effect: runs only while tracing

    S = ctrl.u.shape[0]
    n = x0.shape[1]
    noise = _uniform01(key, (x0.shape[0], S, n + 2), x0.dtype)   # all randomness, drawn once

    def one(x_init, v_run):
        def body(x, xs):
            T, r, simp, valid, uv, Hn, hn, v = xs
            u, _, out = control_step(x, T, r, simp, valid, uv)
            xbar = A @ x + B @ u
            w = _disturbance(v, wd, ball, mode_idx, Hn, hn, xbar)
            xn = xbar + w
            return xn, (xn, u, w, out, set_violation(xn, Hn, hn))

        xs = (ctrl.T, ctrl.r, ctrl.simplices, ctrl.valid, ctrl.u, ctrl.H[1:], ctrl.h[1:], v_run)
        _, (X, U, Wt, out, viol) = jax.lax.scan(body, x_init, xs)
        v0 = set_violation(x_init, ctrl.H[0], ctrl.h[0])
        return (jnp.concatenate([x_init[None], X], 0), U, Wt, out,
                jnp.concatenate([v0[None], viol], 0))

    return jax.vmap(one)(x0, noise)


def rollout(ctrl: EdgeController, A, B, x0, key, W, mode: str = "uniform") -> dict:
    """Closed-loop rollouts of ``ctrl`` (pure JAX, jitted; no host checks).

    Parameters
    ----------
    ctrl : EdgeController
        ``S`` control steps.
    A : (n, n); B : (n, m)
    x0 : (runs, n)
        Initial states.
    key : PRNGKey
    W : Ball or Polytope
        Disturbance set used in the simulation.
    mode : {'uniform', 'boundary', 'adversarial', 'none'}

    Returns
    -------
    dict
        ``x (runs, S+1, n)``, ``u (runs, S, m)``, ``w (runs, S, n)``,
        ``outside (runs, S)`` (barycentric, at control time),
        ``violation (runs, S+1)`` (``max(H x - h)`` of the set the state must be in).
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    dtype = ctrl.H.dtype
    if dtype == jnp.float64 and not jax.config.jax_enable_x64:
        raise ValueError("a float64 rollout needs x64: call inside `with jax.enable_x64(True)`")
    x0 = jnp.asarray(x0, dtype)
    wd, ball = _w_data(W, x0.shape[1], dtype)
    X, U, Wt, out, viol = _rollout(ctrl, jnp.asarray(A, dtype), jnp.asarray(B, dtype), x0, key,
                                   wd, jnp.asarray(MODES.index(mode), jnp.int32), ball)
    return dict(x=X, u=U, w=Wt, outside=out, violation=viol)


# ------------------------------------------------------------------ host checks
def _violation(P: Polytope, X: np.ndarray) -> np.ndarray:
    """``max(H x - h)`` of ``P`` for float64 points ``X (..., n)``, facet by facet in elementwise
    float64 (as :meth:`Polytope.violation`, without a stacked matmul: many points, few facets)."""
    H, h = P.H, P.h
    out = None
    for f in range(len(h)):
        v = X[..., 0] * H[f, 0]
        for j in range(1, X.shape[-1]):
            v += X[..., j] * H[f, j]
        v -= h[f]
        out = v if out is None else np.maximum(out, v, out=out)
    return out


def in_cells(decomp, X, tol: float = 1e-9, cells=None, first=()) -> np.ndarray:
    """Whether points lie in any of ``cells`` (default: all), up to ``tol``. ``X (..., n)`` -> ``(...)``.

    The cells in ``first`` (those most points lie in, e.g. a plan's) are tried first, and each
    further cell only on the points no cell has taken yet: the same answer as trying every cell
    on every point, at a cost that hardly grows with the number of cells.
    """
    X = np.asarray(X, float)
    shape = X.shape[:-1]
    ids = list(range(decomp.n_cells) if cells is None else cells)
    if len(first):
        allowed = set(ids)
        head = [i for i in dict.fromkeys(int(c) for c in first) if i in allowed]
        seen = set(head)
        ids = head + [i for i in ids if i not in seen]
    pts = X.reshape(-1, X.shape[-1])
    out = np.zeros(len(pts), bool)
    todo = np.arange(len(pts))
    for i in ids:
        if not todo.size:
            break
        inside = _violation(decomp.cells[i], pts if todo.size == len(pts) else pts[todo]) <= tol
        out[todo[inside]] = True
        todo = todo[~inside]
    return out.reshape(shape)


def in_obstacle_interior(decomp, X, tol: float = 1e-9) -> np.ndarray:
    """Whether points lie in ``int O``: strictly inside an obstacle and in no cell up to ``tol``.

    Parameters
    ----------
    decomp : CellDecomposition
    X : array, shape (..., n)

    Returns
    -------
    ndarray of bool, shape (...)
    """
    X = np.asarray(X, float)
    hit = np.zeros(X.shape[:-1], bool)
    for o in decomp.obstacles:
        if isinstance(o, Polytope):
            hit |= _violation(o, X) < -tol
        else:
            if X.shape[-1] != 2:
                raise ValueError("shapely obstacles need 2-D states")
            hit |= shapely.contains_xy(o, X[..., 0], X[..., 1])
    if hit.any():                              # only the points inside an obstacle need the cells
        hit[hit] = ~in_cells(decomp, X[hit], tol)
    return hit


def _first_true(F):
    """Index of the first True along the last axis, ``-1`` if none."""
    return np.where(F.any(-1), np.argmax(F, axis=-1), -1)


@dataclass
class SimulationResult:
    """Closed-loop runs and their checks (see the module docstring).

    Attributes
    ----------
    trajectories : (runs, S+1, n);  inputs : (runs, S, m);  disturbances : (runs, S, n)
    violation : (runs, S+1)   ``max(H x - h)`` of the current tube set (``<= 0`` inside)
    outside : (runs, S)       barycentric outside amount at control time
    obstacle_entry, tube_exit, reached_all : (runs,) bool
    first_obstacle_time, first_exit_time : (runs,) int, ``-1`` if never
    targets_reached : (runs, K) bool    per segment
    workspace_exit : (runs,) bool       a state outside the workspace: outside its ``domain``
                                        when it has one, else in no cell and in no obstacle
    input_violation : (runs,)           ``max(H_u u - h_u)`` (``<= 0``: in ``U``)
    state_constraints : dict            ``{name: Halfspaces}`` checked (``system.state_constraints``)
    outside_state_constraints : dict    ``{name: (runs,) int}``: states of each run outside it by more
                                        than ``tol``; :attr:`state_constraint_exit` flags such runs
    """

    trajectories: np.ndarray
    inputs: np.ndarray
    disturbances: np.ndarray
    violation: np.ndarray
    outside: np.ndarray
    obstacle_entry: np.ndarray
    first_obstacle_time: np.ndarray
    tube_exit: np.ndarray
    first_exit_time: np.ndarray
    targets_reached: np.ndarray
    reached_all: np.ndarray
    workspace_exit: np.ndarray
    input_violation: np.ndarray
    plan: Plan
    mode: str
    seed: int
    tol: float
    meta: dict = field(default_factory=dict)
    state_constraints: dict = field(default_factory=dict)
    outside_state_constraints: dict = field(default_factory=dict)

    @property
    def n_runs(self) -> int:
        return int(self.trajectories.shape[0])

    @property
    def state_constraint_exit(self) -> np.ndarray:
        """``(runs,)`` bool: runs with a state outside some state constraint (such a run is unsafe)."""
        out = np.zeros(self.n_runs, bool)
        for c in self.outside_state_constraints.values():
            out |= np.asarray(c) > 0
        return out

    def summary(self) -> dict:
        """Counts over runs (plain Python types); ``outside_state_constraints`` counts *states*
        (over all runs and steps) outside each state constraint, ``{}`` when the system has none."""
        return {
            "runs": self.n_runs,
            "steps": int(self.inputs.shape[1]),
            "mode": self.mode,
            "seed": self.seed,
            "obstacle_entries": int(self.obstacle_entry.sum()),
            "tube_exits": int(self.tube_exit.sum()),
            "workspace_exits": int(self.workspace_exit.sum()),
            "runs_reaching_all_targets": int(self.reached_all.sum()),
            "targets_reached_per_segment": [int(c) for c in self.targets_reached.sum(0)],
            "max_tube_violation": float(np.max(self.violation)) if self.violation.size else 0.0,
            "max_outside": float(np.max(self.outside)) if self.outside.size else 0.0,
            "max_input_violation": float(np.max(self.input_violation)) if self.n_runs else 0.0,
            "tol": self.tol,
            "outside_state_constraints": {k: int(np.sum(c)) for k, c in self.outside_state_constraints.items()},
        }


def simulate(ts, plan: Plan, n_runs: int = 100, mode: str = "uniform", seed: int = 0,
             x0=None, W=None, tol: float | None = None, ctrl: EdgeController | None = None,
             progress=False, chunk_runs: int = CHUNK_RUNS) -> SimulationResult:
    """Simulate Algorithm 3 along ``plan`` for many runs and check every run.

    Parameters
    ----------
    ts : TransitionSystem
    plan : Plan
    n_runs : int
        Runs when ``x0`` is not given (initial states uniform in the first cell).
    mode : {'uniform', 'boundary', 'adversarial', 'none'}
    seed : int
        ``jax.random.PRNGKey(seed)`` drives initial states and disturbances.
    x0 : array (runs, n), optional
    W : Ball or Polytope, optional
        Disturbance set of the simulation (default: the design ``ts.system.W``);
        a larger one shows that violations are detected.
    tol : float, optional
        Violation above which a tube exit is counted (default ``1e-9``).
    ctrl : EdgeController, optional
        Precomputed :func:`plan_controller` (e.g. a modified tube); it must hold float64 data.
    progress : bool or tqdm-like
        ``True``: a tqdm bar on stderr whose total is the number of runs, advancing as
        chunks of runs are checked; a tqdm-like object (``update(k)``) is advanced instead.
    chunk_runs : int
        Runs checked at a time (:data:`CHUNK_RUNS`).

    Returns
    -------
    SimulationResult
        The same for every ``progress`` and ``chunk_runs``.

    Notes
    -----
    Everything here reports safety, so it always runs in float64 (inside
    ``jax.enable_x64(True)``, whatever the global ``jax_enable_x64``): in float32 the
    rounding of a state on a tube facet alone exceeds ``1e-9`` and shows up as false alarms.
    """
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if isinstance(chunk_runs, bool) or not isinstance(chunk_runs, (int, np.integer)) or chunk_runs < 1:
        raise ValueError(f"chunk_runs must be an integer >= 1, got {chunk_runs!r}")
    with jax.enable_x64(True):
        return _simulate(ts, plan, n_runs, mode, seed, x0, W, 1e-9 if tol is None else float(tol), ctrl,
                         progress, int(chunk_runs))


def _check_runs(decomp, plan, X, viol, tol: float, constraints=None) -> dict:
    """The per-state host checks of some runs (``X (runs, S+1, n)``, ``viol (runs, S+1)``) as per-run arrays;
    ``constraints`` (``{name: Halfspaces}``) adds ``outside_<name>``, states outside it per run."""
    obst = in_obstacle_interior(decomp, X)
    exits = ~(viol <= tol)                   # a NaN state is an exit too
    if getattr(decomp, "domain", None) is not None:       # a convex workspace (a box grid's box)
        ws_exit = ~(_violation(decomp.domain, X) <= 1e-9)
    else:
        ws_exit = ~in_cells(decomp, X, 1e-9, first=plan.cells) & ~obst
    times = plan.segment_times
    reached = np.stack([in_cells(decomp, X[:, t], 1e-9, plan.target_cells[k])
                        for k, t in enumerate(times)], axis=1) if times else np.ones((len(X), 0), bool)
    outside = {f"outside_{k}": c for k, c in count_outside_state_constraints(constraints or {}, X, tol).items()}
    return dict(obstacle_entry=obst.any(1), first_obstacle_time=_first_true(obst), tube_exit=exits.any(1),
                first_exit_time=_first_true(exits), targets_reached=reached, workspace_exit=ws_exit.any(1),
                **outside)


def _simulate(ts, plan, n_runs, mode, seed, x0, W, tol, ctrl, progress=False,
              chunk_runs: int = CHUNK_RUNS) -> SimulationResult:
    """:func:`simulate` with x64 enabled."""
    if ctrl is None:
        ctrl = plan_controller(ts, plan, jnp.float64)
    dtype = ctrl.H.dtype
    if dtype != jnp.float64:
        raise ValueError(f"the simulation computes in float64; the controller data is {dtype}")
    key = jax.random.PRNGKey(seed)
    kx, kw = jax.random.split(key)
    decomp, sysm = ts.decomposition, ts.system
    if x0 is None:
        x0 = sample_polytope(kx, decomp.cells[plan.cells[0]], int(n_runs), dtype)
    x0 = jnp.atleast_2d(jnp.asarray(x0, dtype))
    own_bar = not hasattr(progress, "update")
    bar = tqdm(total=int(x0.shape[0]), desc=f"simulating ({mode})", unit="run", disable=not progress,
               leave=False) if own_bar else progress
    try:
        out = rollout(ctrl, sysm.A, sysm.B, x0, kw, sysm.W if W is None else W, mode)
        X, U, Wt, outside, viol = (np.asarray(out[k], float)
                                   for k in ("x", "u", "w", "outside", "violation"))
        parts = []
        for a in range(0, max(len(X), 1), chunk_runs):          # the checks: most of the time
            parts.append(_check_runs(decomp, plan, X[a:a + chunk_runs], viol[a:a + chunk_runs], tol,
                                     sysm.state_constraints))
            bar.update(len(X[a:a + chunk_runs]))
    finally:
        if own_bar:
            bar.close()
    flags = {k: np.concatenate([p_[k] for p_ in parts], axis=0) for k in parts[0]}
    uviol = np.max(_violation(sysm.U, U), axis=1) if U.shape[1] else np.full(len(X), -np.inf)
    return SimulationResult(
        trajectories=X, inputs=U, disturbances=Wt, violation=viol, outside=outside,
        obstacle_entry=flags["obstacle_entry"], first_obstacle_time=flags["first_obstacle_time"],
        tube_exit=flags["tube_exit"], first_exit_time=flags["first_exit_time"],
        targets_reached=flags["targets_reached"], reached_all=flags["targets_reached"].all(1),
        workspace_exit=flags["workspace_exit"], input_violation=uviol, plan=plan, mode=mode, seed=int(seed),
        tol=float(tol), state_constraints=dict(sysm.state_constraints),
        outside_state_constraints={k: flags[f"outside_{k}"] for k in sysm.state_constraints})


def simulate_edge(ts, k: int, n_runs: int = 100, mode: str = "uniform", seed: int = 0,
                  x0=None, W=None, tol: float | None = None,
                  ctrl: EdgeController | None = None, progress=False) -> SimulationResult:
    """:func:`simulate` along the single edge ``k`` (target: its destination cell)."""
    return simulate(ts, plan_edge(ts, k), n_runs, mode, seed, x0, W, tol, ctrl, progress=progress)


def summary_violations(s: dict) -> list[str]:
    """What a simulation summary (:meth:`SimulationResult.summary`, or a specification run's) shows
    going wrong, one phrase each; empty when every run was safe and met every target."""
    bad = [f"{s[k]} runs with {k.replace('_', ' ')}" for k in ("obstacle_entries", "tube_exits", "workspace_exits")
           if s[k]]
    if s["runs_reaching_all_targets"] != s["runs"]:
        bad.append(f"{s['runs'] - s['runs_reaching_all_targets']} runs missing a target")
    bad += [f"{c} states outside the state constraint {k}" for k, c in s.get("outside_state_constraints", {}).items()
            if c]
    if s.get("avoided_region_entries"):
        bad.append(f"{s['avoided_region_entries']} runs entering an avoided region")
    if "runs_satisfying_spec" in s and s["runs_satisfying_spec"] != s["runs"]:
        bad.append(f"{s['runs'] - s['runs_satisfying_spec']} runs violating the specification")
    return bad
