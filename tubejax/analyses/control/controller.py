"""Low-level control (Algorithm 1) in closed form, jit- and vmap-friendly (why these weights are a
valid choice of Algorithm 1: docs/math/control.md#tube-controller).

The weights of ``x in Q_l`` come from a **fixed triangulation** (scipy ``Delaunay``, once per edge on
the host) of the source cell's points for ``l = 0`` and of ``Z`` for ``l >= 1``, carried to ``Q_l``;
the simplex with the largest minimum barycentric coordinate is chosen (first on ties). ``x`` outside
``Q_l``: ``lambda`` is clipped and renormalised, so ``u`` stays in ``U``, and how far outside is
returned, never hidden.
"""

from __future__ import annotations

from functools import lru_cache
from math import factorial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from scipy.spatial import ConvexHull, Delaunay

from ...abstraction.product_abstraction import ProductTube
from ...errors import InputError
from ...lp.evidence.registry import FORMULATIONS, tube_methods
from ...model.zshape.kinds import source_points

__all__ = ["EdgeController", "Triangulation", "triangulate", "edge_controller", "controller_step_at",
           "plan_controller", "stack_controllers", "control_step", "barycentric",
           "set_violation", "require_tubes", "axis_scales", "PAD_H"]

#: Right-hand side of padded (always satisfied) facet rows.
PAD_H = 1e300


class Triangulation(NamedTuple):
    """A fixed triangulation of ``co(points)`` with barycentric maps.

    simplices : int array (n_s, n + 1), indices into the points
    T : array (n_s, n, n), r : array (n_s, n)
        ``beta[:n] = T_s (x - r_s)``, ``beta[n] = 1 - sum beta[:n]``.
    """

    simplices: np.ndarray
    T: np.ndarray
    r: np.ndarray


def triangulate(points: np.ndarray) -> Triangulation:
    """Delaunay triangulation of ``co(points)``, any dimension ``n >= 1``.

    Degenerate (flat) simplices that Qhull may return for co-spherical points
    are dropped; the remaining simplices must cover the hull (checked by volume).

    Parameters
    ----------
    points : ndarray, shape (n_v, n)

    Returns
    -------
    Triangulation
    """
    P = np.asarray(points, float)
    n_v, n = P.shape
    if n == 1:
        order = np.argsort(P[:, 0])
        simp = np.stack([order[:-1], order[1:]], axis=1)
    else:
        try:
            simp = Delaunay(P).simplices
        except Exception as exc:          # QhullError for flat point sets
            raise ValueError(f"triangulation failed: the points do not span R^{n} ({exc})") from None
    simp = np.sort(simp, axis=1)        # deterministic vertex order inside each simplex
    Ts, rs, keep, vols = [], [], [], []
    for s in simp:
        r = P[s[n]]
        M = (P[s[:n]] - r).T            # x - r = M c
        vol = abs(np.linalg.det(M))
        scale = np.max(np.abs(M)) ** n if M.size else 1.0
        if not vol > 1e-12 * scale:
            continue
        keep.append(s)
        Ts.append(np.linalg.inv(M))
        rs.append(r)
        vols.append(vol)
    if not keep:
        raise ValueError("triangulation failed: the points do not span R^n")
    simp = np.array(keep, dtype=np.int32)
    hull_vol = _hull_volume(P)
    if abs(sum(vols) - hull_vol) > 1e-8 * max(hull_vol, 1e-300):
        raise ValueError(f"triangulation does not cover the hull: simplex volume {sum(vols)} "
                         f"vs hull {hull_vol}")
    return Triangulation(simp, np.array(Ts), np.array(rs))


def _hull_volume(P):
    if P.shape[1] == 1:
        return float(P.max() - P.min())

    return float(ConvexHull(P).volume) * factorial(P.shape[1])   # in |det| units


class EdgeController(NamedTuple):
    """Stacked control data, padded to common sizes so a whole plan is one stack (``S`` control
    steps, ``n_s`` simplices, ``n_v`` vertices, ``n_f`` facets).

    T : (S, n_s, n, n); r : (S, n_s, n); simplices : (S, n_s, n + 1) int32; valid : (S, n_s) bool
        Each step's simplices, barycentric maps ``c = T_s (x - r_s)``, ``beta = (c, 1 - sum c)``.
    u : (S, n_v, m)
        The vertex inputs of steps ``0..S-1``.
    H : (S + 1, n_f, n); h : (S + 1, n_f)
        The set the state must lie in at times ``0..S`` (unit rows; padded rows ``0 x <= 1e300``).
    """

    T: jax.Array
    r: jax.Array
    simplices: jax.Array
    valid: jax.Array
    u: jax.Array
    H: jax.Array
    h: jax.Array

    @property
    def n_steps(self) -> int:
        return int(self.u.shape[0])


@lru_cache(maxsize=4096)
def _tri_bytes(buf: bytes, shape: tuple) -> Triangulation:
    return triangulate(np.frombuffer(buf, dtype=float).reshape(shape))


def _tri_cached(points) -> Triangulation:
    """:func:`triangulate`, memoised on the point coordinates."""
    P = np.ascontiguousarray(points, dtype=float)
    return _tri_bytes(P.tobytes(), P.shape)


def _scaled_inverse(T, eps) -> np.ndarray:
    """Barycentric maps ``T diag(1 / eps)`` of ``Q_l = p_l + diag(eps) Z`` from those of ``Z``
    (``T (n_s, n, n)``; ``eps`` a number or one per axis, shape ``(n,)``), shape of ``T``.

    A point tube (an ``eps`` of 0, possible only when ``W`` has no interior; or a ``T / eps`` that
    overflows) gets ``T = 0``: ``Q_l = {p_l}``, where every vertex input is valid, and the
    weights are then fixed (one vertex of the first simplex). The state is still checked
    against ``Q_l`` through its H-rep.
    """
    eps = np.asarray(eps, float)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        out = T / eps
    return out if np.all(eps > 0) and np.all(np.isfinite(out)) else np.zeros_like(T)


def axis_scales(tube, n: int) -> np.ndarray:
    """The scale of each axis at each step, ``(L, n)``: ``eps_l`` on every axis for a :class:`Tube`,
    ``eps_{l, g}`` on the axes of group ``g`` for a :class:`~tubejax.abstraction.product_abstraction.ProductTube`."""
    eps = np.asarray(tube.eps, float)
    if isinstance(tube, ProductTube):
        return eps[:, np.asarray(tube.group_of_axis)]
    return np.repeat(eps[:, None], n, axis=1)


def require_tubes(ts, edges=None) -> None:
    """Refuse a system whose edges ``edges`` (default all) store no tube: Algorithm 1 needs them.

    Raises
    ------
    InputError
        Naming the method (one whose record has no tubes: ``exact2d`` stores no evidence, ``openloop``
        an input plan per vertex) or the first edge without a tube.
    """
    if ts.method not in tube_methods():
        record = FORMULATIONS.get(ts.method)
        what = ("no tubes" if record is None else "no evidence (it solves no LP)" if not record.solves_lp
                else f"evidence ({', '.join(record.evidence_names)}) that is not a tube")
        raise InputError(f"method {ts.method!r}: the system stores {what}, so there is no tube controller "
                         f"(Algorithm 1) to simulate; use a system of method {' or '.join(map(repr, tube_methods()))}")
    ks = range(ts.n_edges) if edges is None else edges
    bad = next((int(k) for k in ks if ts.tubes[int(k)] is None), None)
    if bad is not None:
        e = ts.edges[bad]
        raise InputError(f"edge {bad} ({e.src}->{e.dst}, L={e.L}): no tube stored, so Algorithm 1 cannot steer "
                         "along it")


def _row_scales(Hz: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """The scale of each facet row of ``Z`` at each step, ``(L, n_f)``, from the axes' ``(L, n)``.

    ``diag(s) Z`` has the facets of ``Z`` moved by ``s`` when every row lies in axes of one scale
    (a product ``Z`` scaled per axis group: each facet of a product is a facet of one factor).

    Raises
    ------
    InputError
        A row of ``Z`` across axes of different scales (then ``diag(s) Z`` has other facets).
    """
    on = np.abs(Hz) > 1e-12                                           # (n_f, n)
    first = np.argmax(on, axis=1)
    out = scale[:, first]                                             # (L, n_f)
    if not np.all(np.where(on[None], scale[:, None, :] == out[:, :, None], True)):
        raise InputError("a tube scaled per axis group needs a cross-section Z whose facets each lie in one "
                         "group's axes (a product Z); this Z has a facet across groups")
    return out


def _edge_arrays(ts, k):
    """Unpadded numpy arrays of edge ``k`` (lists over steps)."""
    e, tube = ts.edges[k], ts.tubes[k]
    P = ts.decomposition.cells[e.src]
    Z = ts.z_of(e.src, e.dst)
    L = int(e.L)
    p, u = np.asarray(tube.p, float), np.asarray(tube.u, float)
    scale = axis_scales(tube, P.dim)                                  # (L, n)
    tri_P = _tri_cached(source_points(P, Z.n_vertices).vertices)     # the points u[0] belongs to
    tri_Z = _tri_cached(Z.vertices)
    Ts, rs, simps, us = [tri_P.T], [tri_P.r], [tri_P.simplices], [u[0]]
    for l in range(1, L):
        Ts.append(_scaled_inverse(tri_Z.T, scale[l - 1]))
        rs.append(p[l - 1] + scale[l - 1] * tri_Z.r)
        simps.append(tri_Z.simplices)
        us.append(u[l])
    zn = np.linalg.norm(Z.H, axis=1)
    Hz, hz = Z.H / zn[:, None], Z.h / zn
    row_scale = _row_scales(Hz, scale)                                # (L, n_f)
    Hs, hs = [P.H], [P.h]
    for l in range(1, L + 1):        # Q_l = {x : Hz (x - p_l) <= eps_l hz} (a product tube: its row's group's eps)
        Hs.append(Hz)
        hs.append(Hz @ p[l - 1] + row_scale[l - 1] * hz)
    return Ts, rs, simps, us, Hs, hs


def _pad_stack(arrs, shape_tail, fill, dtype):
    out = np.full((len(arrs),) + shape_tail, fill, dtype=dtype)
    for i, a in enumerate(arrs):
        out[(i,) + tuple(slice(0, s) for s in a.shape)] = a
    return out


def stack_controllers(parts, dtype=None) -> EdgeController:
    """Concatenate edges' data (from :func:`_edge_arrays`) into one padded :class:`EdgeController`.

    Consecutive edges share a time instant: the check set at the end of edge
    ``e`` (its ``Q_L``) is kept, the next edge's ``P_i`` check set is dropped. A part that
    appears several times (the same object: an edge a plan repeats, a patrol's cycles) is
    padded once and its block copied.
    """
    if dtype is None:
        dtype = jnp.float64 if jax.config.jax_enable_x64 else jnp.float32
    if jnp.dtype(dtype) == jnp.float64 and not jax.config.jax_enable_x64:
        raise ValueError("float64 controller data needs x64: call inside `with jax.enable_x64(True)` "
                         "(tubejax.analyses.control.simulate does)")
    distinct = list({id(p): p for p in parts}.values())
    simps = [s for p in distinct for s in p[2]]
    us = [u for p in distinct for u in p[3]]
    Hs = list(parts[0][4]) + [H for p in {id(p): p for p in parts[1:]}.values() for H in p[4][1:]]
    n = Hs[0].shape[1]
    n_s = max(s.shape[0] for s in simps) if simps else 1
    n_v = max(u.shape[0] for u in us) if us else 1
    m = us[0].shape[1] if us else 1
    n_f = max(H.shape[0] for H in Hs)
    blocks = {}
    for p in distinct:
        T, r, s, u, H, h = p
        valid = [np.ones(x.shape[0], bool) for x in s]
        blocks[id(p)] = (_pad_stack(T, (n_s, n, n), 0.0, float), _pad_stack(r, (n_s, n), 0.0, float),
                         _pad_stack(s, (n_s, n + 1), 0, np.int32), _pad_stack(valid, (n_s,), False, bool),
                         _pad_stack(u, (n_v, m), 0.0, float), _pad_stack(H, (n_f, n), 0.0, float),
                         _pad_stack(h, (n_f,), PAD_H, float))

    def cat(a: int, shared_start: bool = False):
        """Block ``a`` of every part in order; ``shared_start``: later parts without their first row."""
        return np.concatenate([blocks[id(p)][a][1:] if shared_start and j else blocks[id(p)][a]
                               for j, p in enumerate(parts)])

    return EdgeController(
        T=jnp.asarray(cat(0), dtype), r=jnp.asarray(cat(1), dtype), simplices=jnp.asarray(cat(2)),
        valid=jnp.asarray(cat(3)), u=jnp.asarray(cat(4), dtype),
        H=jnp.asarray(cat(5, shared_start=True), dtype), h=jnp.asarray(cat(6, shared_start=True), dtype))


def edge_controller(ts, k: int, dtype=None) -> EdgeController:
    """Controller data of edge ``k`` of ``ts``: ``S = L`` control steps, ``L + 1`` check sets."""
    require_tubes(ts, [k])
    return stack_controllers([_edge_arrays(ts, int(k))], dtype)


def plan_controller(ts, plan, dtype=None) -> EdgeController:
    """Controller data of a whole :class:`~tubejax.analyses.control.planner.Plan` (``S = plan.cost``)."""
    if not plan.edges:
        P = ts.decomposition.cells[plan.cells[0]]
        n, m = P.dim, ts.system.m
        part = ([], [], [], [], [P.H], [P.h])
        c = stack_controllers([part], dtype)
        z = jnp.zeros
        return c._replace(T=z((0, 1, n, n), c.H.dtype), r=z((0, 1, n), c.H.dtype),
                          simplices=z((0, 1, n + 1), jnp.int32), valid=z((0, 1), bool),
                          u=z((0, 1, m), c.H.dtype))
    require_tubes(ts, plan.edges)
    parts = {k: _edge_arrays(ts, k) for k in dict.fromkeys(int(k) for k in plan.edges)}
    return stack_controllers([parts[int(k)] for k in plan.edges], dtype)


# ---------------------------------------------------------------- run time (JAX)
def barycentric(x, T, r, valid):
    """Barycentric coordinates of ``x`` in every simplex.

    Parameters
    ----------
    x : (n,); T : (n_s, n, n); r : (n_s, n); valid : (n_s,) bool

    Returns
    -------
    beta : (n_s, n + 1)
    score : (n_s,)   ``min beta`` per simplex (``-inf`` for padded simplices)
    """
    c = jnp.einsum("sij,sj->si", T, x - r)
    beta = jnp.concatenate([c, 1.0 - jnp.sum(c, axis=-1, keepdims=True)], axis=-1)
    score = jnp.where(valid, jnp.min(beta, axis=-1), -jnp.inf)
    return beta, score


def set_violation(x, H, h):
    """``max(H x - h)`` (positive outside; a distance for unit rows). ``x (n,)``, ``H (n_f, n)``, ``h (n_f,)``."""
    return jnp.max(H @ x - h)


def control_step(x, T, r, simplices, valid, u):
    """One step of Algorithm 1 for a single state.

    Parameters
    ----------
    x : (n,)
    T, r, simplices, valid : one step of an :class:`EdgeController`
        shapes ``(n_s, n, n)``, ``(n_s, n)``, ``(n_s, n + 1)``, ``(n_s,)``.
    u : (n_v, m)
        Vertex inputs ``u_k(l)``.

    Returns
    -------
    u_x : (m,)
        The input ``sum_k lambda_k u_k(l)``.
    lam : (n_v,)
        The weights (``>= 0``, sum 1; zero outside the chosen simplex).
    outside : scalar
        ``max(0, -min beta)`` of the chosen simplex: 0 iff ``x in Q_l``.
    """
    beta, score = barycentric(x, T, r, valid)
    s = jnp.argmax(score)
    b = beta[s]
    outside = jnp.maximum(-score[s], 0.0)
    bc = jnp.maximum(b, 0.0)
    bc = bc / jnp.sum(bc)
    lam = jnp.zeros(u.shape[0], x.dtype).at[simplices[s]].add(bc)
    return lam @ u, lam, outside


def controller_step_at(ctrl: EdgeController, t, x):
    """:func:`control_step` using step ``t`` of ``ctrl`` (``t`` may be traced)."""
    return control_step(x, ctrl.T[t], ctrl.r[t], ctrl.simplices[t], ctrl.valid[t], ctrl.u[t])
