"""Batched restarted Halpern PDHG for margin-form LPs, matrix-free (docs/explanation/solvers.md#the-batched-path).

One instance is ``min c^T z  s.t.  K z <= g,  lo <= z <= hi`` (every variable boxed; the margin form
has ``c = -e_t``), ``K`` given only through ``matvec``, ``rmatvec``. After PDLP / cuPDLPx: Ruiz then
Pock-Chambolle scaling (``||K~|| <= 1``), reflected Halpern iterations, adaptive restarts and a
primal-weight update. Leaves of the pytree vectors carry the batch axis LAST; instances never
interact, so a trajectory does not depend on its batch. :func:`pdhg_init` scales on the host,
:func:`pdhg_step` iterates, :func:`pdhg_terminate` checks (certificates from :mod:`.certify`),
:func:`make_pdhg_runner` owns the loop. Data-dependent failures are statuses, never exceptions.
:attr:`PdhgOptions.mode` ``'sign'`` stops once the optimum's sign is settled, ``'optimise'`` once the
rigorous dual bound is within ``gap_tol`` of the best primal objective
(:func:`~.objective_bounds.make_objective_certify`).
"""

from __future__ import annotations

import enum

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np


__all__ = ["PdhgOptions", "PdhgProblem", "PdhgState", "ScalingOperator", "pdhg_init", "pdhg_scaling", "ruiz_passes",
           "RUIZ_AUTO_PASSES", "pdhg_step", "pdhg_terminate", "make_pdhg_runner", "tree_sum",
           "tree_sumsq", "RUNNING", "FEASIBLE", "INFEASIBLE", "NEAR_ZERO", "MAX_ITERS", "NUMERICAL", "PAD",
           "OPTIMAL", "STATUS_NAMES", "PdhgStatus"]

class PdhgStatus(enum.IntEnum):
    """An instance's status in the batched PDHG state (an ``int32`` per instance on the device)."""

    RUNNING = 0          # still iterating
    FEASIBLE = 1         # a primal point satisfies the rows to ``feas_tol``
    INFEASIBLE = 2       # a dual bound certifies the optimum below ``-margin_safety``
    NEAR_ZERO = 3        # nonnegative, or too close to 0 to settle cheaply: an exact solver decides
    MAX_ITERS = 4        # the iteration cap
    NUMERICAL = 5        # a NaN or an infinity
    PAD = 6              # an empty slot of the pool
    OPTIMAL = 7          # optimise mode: the duality gap is below ``gap_tol``


#: The statuses as plain ints (what the jitted code compares and stores).
RUNNING, FEASIBLE, INFEASIBLE, NEAR_ZERO, MAX_ITERS, NUMERICAL, PAD, OPTIMAL = (int(s) for s in PdhgStatus)
#: Each status's name, by value (the keys of ``stats.status_counts``).
STATUS_NAMES = tuple(s.name.lower() for s in PdhgStatus)


class PdhgOptions(NamedTuple):
    """Static solver options (hashable: they key the jit cache).

    check_every : iterations between certificate checks
    checks_per_call : certificate checks per jitted call (a chunk is ``check_every * checks_per_call``)
    max_iters : iteration cap (then status ``MAX_ITERS``, or ``NEAR_ZERO``, see ``cap_tol``;
        docs/explanation/performance.md#pdhg-iteration-cap)
    eta : step size relative to the bound ``||K~|| <= 1``
    reflect : Halpern reflection ``rho`` in ``(0, 1]``
    ruiz_iters : 2-norm Ruiz passes before Pock-Chambolle scaling, or ``'auto'`` (:func:`ruiz_passes`;
        docs/explanation/performance.md#ruiz-scaling-passes)
    restart_sufficient, restart_necessary, restart_artificial : restart thresholds
    feas_tol : largest primal violation (unit rows, ``t = 0``) accepted as feasible
    margin_safety : a dual bound below ``-margin_safety`` certifies ``t* < 0``
    zero_after, zero_tol : after ``zero_after`` iterations, a primal violation ``<= zero_tol``
        without a feasibility certificate gives ``NEAR_ZERO`` (zero-margin edges never certify):
        an exact solver decides
    cap_tol : at the iteration cap, a primal violation ``<= cap_tol`` gives ``NEAR_ZERO`` (a likely
        edge, for HiGHS) rather than ``MAX_ITERS``
    mode : ``'sign'`` (decide the sign of the margin; the verdict path) or ``'optimise'``
        (run to a duality gap ``<= gap_tol``; see the module docstring)
    gap_tol : optimise mode: an instance is ``OPTIMAL`` once ``upper - lower <= gap_tol``
        (absolute, in the objective's units: radius units for the radius form)
    """

    check_every: int = 16
    checks_per_call: int = 8
    max_iters: int = 1024
    eta: float = 0.998
    reflect: float = 1.0
    ruiz_iters: int | str = "auto"
    restart_sufficient: float = 0.2
    restart_necessary: float = 0.8
    restart_artificial: float = 0.25
    feas_tol: float = 1e-9
    margin_safety: float = 1e-7
    zero_after: int = 64
    zero_tol: float = 1e-4
    cap_tol: float = 1e-2
    mode: str = "sign"
    gap_tol: float = 1e-6


class PdhgProblem(NamedTuple):
    """A batch of LPs (unscaled). ``data`` is the operator's pytree; ``c, lo, hi`` are primal
    pytrees (finite bounds), ``g, mask`` dual pytrees (``mask`` 1 = real row, 0 = padding).
    ``ref`` (optional, flat): the optimise-mode certificate's reference ``(x, col, rows)``
    (:class:`~tubejax.lp.engines.objective_bounds.ObjectiveRef`: a box-feasible point satisfying
    strictly every row in which ``t`` has no coefficient, ``t``'s column and the point's rows);
    ``None`` in the margin form."""

    data: Any
    c: Any
    g: Any
    lo: Any
    hi: Any
    mask: Any
    ref: Any = None


class PdhgState(NamedTuple):
    """Solver state of a batch (scaled space); pytree vectors, per-instance scalars ``(B,)``."""

    dr: Any                # row scaling (dual pytree)
    dc: Any                # column scaling (primal pytree)
    omega: jax.Array       # primal weight
    x: Any                 # Halpern iterate
    y: Any
    x0: Any                # anchor (the last restart point)
    y0: Any
    k: jax.Array           # iterations since the last restart
    it: jax.Array          # total iterations
    r0: jax.Array          # fixed-point residual at the last restart
    r_prev: jax.Array      # residual at the previous check
    status: jax.Array      # int32
    bound: jax.Array       # best certified upper bound on the optimum of ``max t`` (unscaled)
    viol: jax.Array        # best primal violation (unscaled)
    x_best: Any            # unscaled primal with the smallest violation
    y_cert: Any            # unscaled dual of the last check (the certificate once INFEASIBLE;
                           # in optimise mode the dual of the best bound)
    lo_s: Any = None       # scaled bounds lo / dc, hi / dc, cost dc c and rhs dr g (padded
    hi_s: Any = None       # rows: +inf, so their dual stays 0); precomputed so that the
    c_s: Any = None        # iteration has no division and no mask
    g_s: Any = None


Op = Callable[[Any, Any], Any]
#: Scaled right-hand side of a padded row: ``y + sigma (d k - g)`` stays negative, so its dual stays 0.
_PAD_RHS = 1e30
CertFn = Callable[[PdhgProblem, Any, Any], tuple]

_tm = jax.tree_util.tree_map


def tree_sum(a, xp=jnp):
    """Per-instance sum over every leaf and every axis but the last: ``(B,)``."""
    return sum(xp.sum(v, axis=tuple(range(v.ndim - 1))) for v in jax.tree_util.tree_leaves(a))


def tree_sumsq(a, xp=jnp):
    """Per-instance squared 2-norm ``(B,)``."""
    return tree_sum(_tm(lambda v: v * v, a), xp)


#: Ruiz passes of ``ruiz_iters = 'auto'`` for a tube LP whose state has 3 or more dimensions.
RUIZ_AUTO_PASSES = 2


def ruiz_passes(opts: PdhgOptions, state_dim: int | None = None) -> int:
    """The number of Ruiz passes ``opts.ruiz_iters`` asks for: an integer as given; ``'auto'``
    gives :data:`RUIZ_AUTO_PASSES` when ``state_dim >= 3`` and 0 otherwise (or without a
    ``state_dim``: formulations other than the tube LP keep their unscaled rows)."""
    if opts.ruiz_iters == "auto":
        return RUIZ_AUTO_PASSES if state_dim is not None and state_dim >= 3 else 0
    if isinstance(opts.ruiz_iters, bool) or not isinstance(opts.ruiz_iters, (int, np.integer)) \
            or opts.ruiz_iters < 0:
        raise ValueError(f"PdhgOptions.ruiz_iters: expected 'auto' or an integer >= 0, got {opts.ruiz_iters!r}")
    return int(opts.ruiz_iters)


class ScalingOperator(NamedTuple):
    """The operator ``K`` as the diagonal scaling reads it: ``matvec(data, z)`` and
    ``rmatvec(data, y)`` (pytrees, batch axis last) applied to ``abs_data`` give ``|K|`` and
    ``K^T``'s absolute values, applied to ``sq_data`` the elementwise square ``K o K``."""

    matvec: Op
    rmatvec: Op
    abs_data: Any
    sq_data: Any


def pdhg_scaling(op: ScalingOperator, prob: PdhgProblem, opts: PdhgOptions, xp=np,
                 state_dim: int | None = None):
    """Ruiz (2-norm) then Pock-Chambolle (alpha = 1) diagonal scalings ``dr``, ``dc`` (pytrees).

    After it ``||diag(dr) K diag(dc)||_2 <= 1`` (``op``: ``|K|`` and ``K o K``). Runs on the
    host (``xp = numpy``) or in jit. ``state_dim`` resolves ``ruiz_iters = 'auto'``
    (:func:`ruiz_passes`).
    """
    matvec, rmatvec, abs_data, sq_data = op
    def rsqrt(v):
        return xp.where(v > 0, 1.0 / xp.sqrt(xp.where(v > 0, v, 1.0)), 1.0)

    dr = _tm(xp.ones_like, prob.g)
    dc = _tm(xp.ones_like, prob.lo)
    for _ in range(ruiz_passes(opts, state_dim)):
        rn = matvec(sq_data, _tm(lambda a: a * a, dc))       # squared row norms, before dr^2
        cn = rmatvec(sq_data, _tm(lambda a: a * a, dr))
        dr = _tm(lambda d, v: d * xp.sqrt(rsqrt(d * d * v)), dr, rn)
        dc = _tm(lambda d, v: d * xp.sqrt(rsqrt(d * d * v)), dc, cn)
    rs = matvec(abs_data, dc)                                 # row 1-norms of K~ (before dr)
    cs = rmatvec(abs_data, dr)
    dr = _tm(lambda d, v, m: xp.where(m > 0, d * rsqrt(d * v), 1.0), dr, rs, prob.mask)
    dc = _tm(lambda d, v: d * rsqrt(d * v), dc, cs)
    return dr, dc


def pdhg_init(op: ScalingOperator, prob: PdhgProblem, z_init, opts: PdhgOptions, xp=np,
              state_dim: int | None = None) -> PdhgState:
    """Scale the problem (:func:`pdhg_scaling` with ``op``) and start from ``z_init`` (unscaled
    primal pytree) and ``y = 0``.

    Runs on the host by default (NumPy, any batch size, nothing to compile). ``state_dim``
    resolves ``ruiz_iters = 'auto'`` (:func:`ruiz_passes`).
    """
    dr, dc = pdhg_scaling(op, prob, opts, xp, state_dim)
    c_norm = xp.sqrt(tree_sumsq(_tm(lambda a, b: a * b, dc, prob.c), xp))
    g_norm = xp.sqrt(tree_sumsq(_tm(lambda d, g, m: d * g * m, dr, prob.g, prob.mask), xp))
    ok = (g_norm > 1e-10) & (c_norm > 1e-10)
    omega = xp.where(ok, c_norm / xp.where(ok, g_norm, 1.0), 1.0)
    zc = _tm(xp.clip, z_init, prob.lo, prob.hi)
    x = _tm(lambda a, b: a / b, zc, dc)
    y = _tm(xp.zeros_like, prob.g)
    B = omega.shape[0]
    inf = xp.full((B,), xp.inf)
    zero = xp.zeros((B,), np.int32)
    g_s = _tm(lambda d, g, m: xp.where(m > 0, d * g, _PAD_RHS), dr, prob.g, prob.mask)
    return PdhgState(dr, dc, omega, x, y, x, y, zero, zero, inf, inf, zero, inf, inf, zc,
                     _tm(xp.zeros_like, prob.g), _tm(lambda a, d: a / d, prob.lo, dc),
                     _tm(lambda a, d: a / d, prob.hi, dc), _tm(lambda a, d: a * d, prob.c, dc), g_s)


def _T(matvec: Op, rmatvec: Op, prob: PdhgProblem, s: PdhgState, opts: PdhgOptions, x, y):
    """One PDHG operator application ``T(x, y)`` in the scaled space."""
    tau = opts.eta / s.omega
    sigma = opts.eta * s.omega
    kty = rmatvec(prob.data, _tm(jnp.multiply, s.dr, y))
    xh = _tm(lambda x, d, g, c, lo, hi: jnp.clip(x - tau * (d * g + c), lo, hi),
             x, s.dc, kty, s.c_s, s.lo_s, s.hi_s)
    kx = matvec(prob.data, _tm(lambda d, a, b: d * (2.0 * a - b), s.dc, xh, x))
    yh = _tm(lambda y, d, k, g: jnp.maximum(y + sigma * (d * k - g), 0.0), y, s.dr, kx, s.g_s)
    return xh, yh


def pdhg_step(matvec: Op, rmatvec: Op, prob: PdhgProblem, s: PdhgState,
              opts: PdhgOptions) -> PdhgState:
    """One reflected-Halpern iteration ``z <- w ((1+rho) T(z) - rho z) + (1-w) z_0``.

    Instances that are no longer ``RUNNING`` keep iterating harmlessly (their
    outputs ``status, bound, viol, x_best, y_cert`` are frozen by :func:`pdhg_terminate`).
    """
    xh, yh = _T(matvec, rmatvec, prob, s, opts, s.x, s.y)
    kf = s.k.astype(s.omega.dtype)
    w = (kf + 1.0) / (kf + 2.0)
    rho = opts.reflect

    def halpern(h, z, z0):
        return w * ((1.0 + rho) * h - rho * z) + (1.0 - w) * z0

    return s._replace(x=_tm(halpern, xh, s.x, s.x0), y=_tm(halpern, yh, s.y, s.y0), k=s.k + 1,
                      it=s.it + (s.status == RUNNING))


def pdhg_terminate(certify: CertFn, matvec: Op, rmatvec: Op, prob: PdhgProblem, s: PdhgState,
                   opts: PdhgOptions) -> PdhgState:
    """The periodic check: adaptive restart, primal-weight update, certificates, ``status``.

    ``T(z)`` is evaluated once; its fixed-point residual drives the restarts (the thresholds of
    :class:`PdhgOptions`), after which ``T(z)`` is the new anchor and the primal weight moves halfway (in
    log scale) to ``||dy|| / ||dx||``. ``certify(prob, z, y) -> (viol, bound)``, each ``(B,)``, on the
    unscaled ``T(z)``: feasible when ``viol <= feas_tol``, infeasible when the rigorous upper bound
    ``bound`` on ``max t`` is ``< -margin_safety``."""
    xh, yh = _T(matvec, rmatvec, prob, s, opts, s.x, s.y)
    r = jnp.sqrt(s.omega * tree_sumsq(_tm(jnp.subtract, xh, s.x))
                 + tree_sumsq(_tm(jnp.subtract, yh, s.y)) / s.omega)
    kf = s.k.astype(s.omega.dtype)
    r0 = jnp.where(jnp.isfinite(s.r0), s.r0, r)
    restart = ((r <= opts.restart_sufficient * r0)
               | ((r <= opts.restart_necessary * r0) & (r > s.r_prev))
               | (kf >= opts.restart_artificial * s.it.astype(kf.dtype)))
    ddx = jnp.sqrt(tree_sumsq(_tm(jnp.subtract, xh, s.x0)))
    ddy = jnp.sqrt(tree_sumsq(_tm(jnp.subtract, yh, s.y0)))
    ok = restart & (ddx > 1e-10) & (ddy > 1e-10)
    om = jnp.where(ok, jnp.sqrt(s.omega * jnp.where(ok, ddy, 1.0) / jnp.where(ok, ddx, 1.0)), s.omega)

    def pick(a, b):
        return jnp.where(restart, a, b)

    # certificates on the unscaled T(z)
    z = _tm(lambda d, x, lo, hi: jnp.clip(d * x, lo, hi), s.dc, xh, prob.lo, prob.hi)
    yv = _tm(jnp.multiply, s.dr, yh)
    viol, bound = certify(prob, z, yv)
    bound = jnp.where(jnp.isnan(bound), jnp.inf, bound)
    if opts.mode == "optimise":              # keep the dual of the best bound
        yv = _tm(lambda a, b: jnp.where(bound < s.bound, a, b), yv, s.y_cert)
    bound = jnp.minimum(s.bound, bound)
    better = viol < s.viol
    x_best = _tm(lambda a, b: jnp.where(better, a, b), z, s.x_best)
    viol = jnp.minimum(s.viol, jnp.where(jnp.isnan(viol), jnp.inf, viol))
    finite = jnp.isfinite(tree_sum(s.x)) & jnp.isfinite(tree_sum(s.y))
    if opts.mode == "optimise":              # viol = -(lower objective), bound = upper
        st = _optimise_status(viol, bound, finite, s.it, opts)
    else:
        st = _sign_status(viol, bound, finite, s.it, opts)
    run = s.status == RUNNING

    def keep(a, b):
        return jnp.where(run, a, b)

    return s._replace(
        omega=om, x=_tm(pick, xh, s.x), y=_tm(pick, yh, s.y), x0=_tm(pick, xh, s.x0),
        y0=_tm(pick, yh, s.y0), k=jnp.where(restart, 0, s.k),
        r0=jnp.where(restart, jnp.inf, r0), r_prev=jnp.where(restart, jnp.inf, r),
        status=keep(st, s.status).astype(jnp.int32), bound=keep(bound, s.bound),
        viol=keep(viol, s.viol), x_best=_tm(keep, x_best, s.x_best),
        y_cert=_tm(keep, yv, s.y_cert))


def _sign_status(viol, bound, finite, it, opts: PdhgOptions):
    """Sign mode: the margin's sign settled (``FEASIBLE`` / ``INFEASIBLE``) or given up."""
    return jnp.where(viol <= opts.feas_tol, FEASIBLE,
         jnp.where(bound < -opts.margin_safety, INFEASIBLE,
         jnp.where(~finite, NUMERICAL,
         jnp.where(((it >= opts.zero_after) & (viol <= opts.zero_tol))
                   | ((it >= opts.max_iters) & (viol <= opts.cap_tol)),
                   NEAR_ZERO,
         jnp.where(it >= opts.max_iters, MAX_ITERS, RUNNING)))))


def _optimise_status(viol, bound, finite, it, opts: PdhgOptions):
    """Optimise mode: ``OPTIMAL`` once ``upper - lower = bound + viol <= gap_tol``;
    ``INFEASIBLE`` once the optimum is certified negative (``bound < -margin_safety``)."""
    return jnp.where(bound + viol <= opts.gap_tol, OPTIMAL,
           jnp.where(bound < -opts.margin_safety, INFEASIBLE,
           jnp.where(~finite, NUMERICAL,
           jnp.where(it >= opts.max_iters, MAX_ITERS, RUNNING))))


def make_pdhg_runner(matvec: Op, rmatvec: Op, certify: CertFn, opts: PdhgOptions,
                     on_trace: Callable[[], None] | None = None):
    """The driver: a jitted ``run(P, S, min_running, layouts) -> S`` for a batch.

    ``P``, ``S``: the problem and state packed by :class:`tubejax.lp.engines.pool.Layout` (one array
    per dtype), ``layouts = (Layout.of(prob), Layout.of(state))`` static. One ``lax.while_loop`` runs
    up to ``opts.checks_per_call`` rounds of ``opts.check_every`` iterations and a check, stopping
    once at most ``min_running`` instances run (traced: no recompilation). ``on_trace`` is called at
    each trace (tests count recompilations with it).
    """
    def run(P: tuple, S: tuple, min_running, layouts) -> tuple:
        if on_trace is not None:
            on_trace()
        prob, state = layouts[0].unpack(P, jnp), layouts[1].unpack(S, jnp)

        def cond(c):
            i, s = c
            return (i < opts.checks_per_call) & (jnp.sum(s.status == RUNNING) > min_running)

        def body(c):
            i, s = c
            s = jax.lax.fori_loop(0, opts.check_every,
                                  lambda _, s: pdhg_step(matvec, rmatvec, prob, s, opts), s)
            return i + 1, pdhg_terminate(certify, matvec, rmatvec, prob, s, opts)

        return layouts[1].pack(jax.lax.while_loop(cond, body, (jnp.zeros((), jnp.int32), state))[1], jnp)

    return jax.jit(run, static_argnums=3)
