"""Closed-loop stepping of Algorithm 3: disturbance sampling and the jitted rollout (the modes:
docs/math/control.md#closed-loop-simulation).

The plan is one ``lax.scan`` over time, ``vmap``-ed over runs (:func:`rollout`). Polytopes are
sampled exactly, without rejection: a simplex of a fixed triangulation with probability proportional
to its volume, then a Dirichlet(1, ..., 1) point. Nothing here checks a run: failures come back as
arrays for :mod:`~tubejax.analyses.control.run_checks`.
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from scipy.spatial import ConvexHull

from ...model.geometry import Ball, Polytope
from .controller import EdgeController, control_step, set_violation, triangulate

__all__ = ["rollout", "sample_polytope", "trace_count", "MODES"]

MODES = ("uniform", "boundary", "adversarial", "none")
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
