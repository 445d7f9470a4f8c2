"""The margin ``t*(Z)`` of the tube LP as a function of ``Z``, and its envelope-theorem gradient.

Derivation
----------
The margin form of Problem 2 (:func:`tubejax.lp.formulations.tube.dense.build_tube_lp`) is

    t*(Z) = max t   s.t.   a_r(Z) . x + t <= g_r(Z)   (rows r: C2, C3, C4),
                           G_hard x <= g_hard,   lb(Z) <= x <= ub(Z),   t <= t_max,

with ``a_r = ã_r / |n_r|``, ``g_r = g̃_r / |n_r|`` for the raw rows ``(ã_r, g̃_r)`` and their
state-space normals ``n_r`` (a facet row of ``S``, ``P_j`` or ``Z``: the margin is a
state-space distance, docs/math/margins.md#state-space-distances). Its
Lagrangian at a primal-dual optimum ``(x*, t*; y*, d*)`` is

    ℒ(Z) = t* + Σ_r y*_r (g_r(Z) - a_r(Z) . x* - t*) + (bound and hard-row terms),

and where the optimum is unique (so the optimal basis is locally constant) the envelope
theorem gives ``dt*/dZ = ∂ℒ/∂Z`` at fixed ``(x*, y*, d*)``:

    dt*/dZ = Σ_r y*_r ∂/∂Z [ (g̃_r - ã_r . x*) / |n_r| ]  +  Σ_j (-d*_j) ∂ b_j/∂Z ,

i.e. ``∂t*/∂a_rc = -y*_r x*_c`` and ``∂t*/∂g_r = y*_r`` chained through the normalisation.
``y*_r >= 0`` are the row duals and ``d*_j`` the reduced costs of ``min -t`` (HiGHS's
``col_dual``): a column at its upper bound has ``d_j <= 0`` and ``dt*/d ub_j = -d_j``, at its
lower bound ``d_j >= 0`` and ``dt*/d lb_j = -d_j``. ``G_hard`` (a non-box ``U``) and ``t_max``
do not depend on ``Z``.

How ``Z`` (vertices ``z_k``, unit facets ``H_z z <= h_z``) enters the raw rows, for
``q_k(l) = p_l + eps_l z_k`` (``l >= 1``) and ``q_k(0) = v_k``:

* C2 (``l = 1 .. L-1``, facet ``(H_S, h_S)`` of ``S``) and C3 (``l = L``, facets of ``P_j``):
  ``ã = [H_S at p_l, sigma_Z(H_S) at eps_l]``, ``g̃ = h_S``, with ``sigma_Z(a) = max_k a . z_k``
  (one row per facet of ``S``; equivalent to the per-vertex rows for ``eps >= 0``), with
  ``n = H_S``;
* C4 (``l = 0 .. L-1``, vertex ``k``, facet ``f`` of ``Z``):
  ``ã = [H_f A at p_l, H_f A z_k at eps_l, H_f B at u_k(l), -H_f at p_{l+1}, -h_f at eps_{l+1}]``,
  ``g̃ = -sigma_W(H_f)`` (``l >= 1``); for ``l = 0`` the ``p_0, eps_0`` entries are absent and
  ``g̃ = -sigma_W(H_f) - H_f A v_k``. The normal is ``n = H_f``.
* the bounds on ``eps_l`` (:func:`~tubejax.lp.formulations.tube.dense.tube_variable_bounds`)
  depend on ``Z`` through its axis widths ``w_Z = max_k z_k - min_k z_k``:
  ``ub = max(min_i w_X,i / w_Z,i, eps_min)`` (``X = S`` for ``l < L``, ``P_j`` for ``l = L``),
  ``lb = min(max(eps_min, max_i w_W,i / w_Z,i), ub)``.

``H_f, h_f`` and ``z_k`` are themselves smooth functions of the parameters
(:mod:`tubejax.analyses.zshape.params`); JAX differentiates ``ℒ`` through all of it (:func:`lagrangian`).
``sigma_Z`` and the widths are maxima, differentiable wherever the maximiser is unique.

Arrays are padded to a horizon ``L_pad`` (rows and steps beyond an instance's ``L`` carry zero
duals) and facet counts ``f_s, f_t`` (padding repeats a real facet, with zero dual), so one
compiled function serves every instance.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ...model.geometry import Ball

__all__ = ["PairGeometry", "MarginSolution", "SystemArrays", "system_arrays", "pair_geometry",
           "lagrangian", "stack"]


class SystemArrays(NamedTuple):
    """The system's data as arrays: ``A (n, n)``, ``B (n, m)``, ``W`` as a ball radius (``()``,
    ``-1`` for a polytope) or polytope vertices ``(n_w, n)`` (a zero row for a ball), ``w_W (n,)``
    its axis widths."""

    A: np.ndarray
    B: np.ndarray
    radius: np.ndarray
    W_vertices: np.ndarray
    w_W: np.ndarray


def system_arrays(system) -> SystemArrays:
    """:class:`SystemArrays` of a :class:`~tubejax.model.system.LinearSystem`."""
    n = system.n
    if isinstance(system.W, Ball):
        return SystemArrays(system.A, system.B, np.float64(system.W.radius), np.zeros((1, n)),
                            np.full(n, 2.0 * system.W.radius))
    lo, hi = system.W.bounding_box()
    return SystemArrays(system.A, system.B, np.float64(-1.0), system.W.vertices, hi - lo)


def _sigma_w(sa: SystemArrays, a):
    """``sigma_W(a)`` for rows ``a`` of shape ``(..., n)``."""
    if float(sa.radius) >= 0:
        return sa.radius * jnp.linalg.norm(a, axis=-1)
    return jnp.max(a @ jnp.asarray(sa.W_vertices).T, axis=-1)


class PairGeometry(NamedTuple):
    """One ``(pair, L)`` instance without ``Z`` (add a leading batch axis with :func:`stack`).

    Attributes
    ----------
    V : (n_v, n)     source cell vertices ``v_k`` (canonical order)
    HS, hS : (f_s, n), (f_s,)   facets of ``S`` (padded by repeating facet 0)
    HT, hT : (f_t, n), (f_t,)   facets of ``P_j``
    L : () int       horizon
    wS, wT : (n,)    axis widths of ``S`` and ``P_j`` (within the pair's box), for the ``eps`` bounds
    eps_min : ()
    """

    V: np.ndarray
    HS: np.ndarray
    hS: np.ndarray
    HT: np.ndarray
    hT: np.ndarray
    L: np.ndarray
    wS: np.ndarray
    wT: np.ndarray
    eps_min: np.ndarray


class MarginSolution(NamedTuple):
    """A primal-dual optimum of one margin LP, padded to ``L_pad`` (add a batch axis to stack).

    Attributes
    ----------
    t : ()                       the margin ``t*``
    p : (L_pad, n)               ``p_1 .. p_L`` (zeros beyond ``L``)
    eps : (L_pad,)
    u : (L_pad, n_v, m)          ``u_k(0) .. u_k(L-1)``
    y2 : (L_pad, f_s)            C2 duals, ``y2[l - 1]`` for ``l = 1 .. L-1``
    y3 : (f_t,)                  C3 duals
    y4 : (L_pad, n_v, f_z)       C4 duals, ``y4[l]`` for ``l = 0 .. L-1``
    d_eps : (L_pad,)             reduced costs of ``eps_1 .. eps_L`` (``min -t``)
    """

    t: np.ndarray
    p: np.ndarray
    eps: np.ndarray
    u: np.ndarray
    y2: np.ndarray
    y3: np.ndarray
    y4: np.ndarray
    d_eps: np.ndarray


def _pad_rows(H, h, f):
    k = f - H.shape[0]
    if k < 0:
        raise ValueError(f"cannot pad {H.shape[0]} facets to {f}")
    return np.vstack([H, np.repeat(H[:1], k, axis=0)]), np.concatenate([h, np.repeat(h[:1], k)])


def pair_geometry(prob, f_s: int, f_t: int) -> PairGeometry:
    """:class:`PairGeometry` of a :class:`~tubejax.lp.formulations.tube.dense.TubeProblem` (its ``Z`` unused).

    The widths are those of :func:`~tubejax.lp.formulations.tube.dense.tube_variable_bounds_batch`.
    """
    blo, bhi = (np.asarray(b, float) for b in prob.box)
    widths = []
    for P in (prob.safe, prob.target):
        lo, hi = P.bounding_box()
        lo, hi = np.maximum(lo, blo), np.minimum(hi, bhi)
        widths.append(np.maximum(hi, lo) - lo)
    HS, hS = _pad_rows(prob.safe.H, prob.safe.h, f_s)
    HT, hT = _pad_rows(prob.target.H, prob.target.h, f_t)
    return PairGeometry(np.asarray(prob.source.vertices, float), HS, hS, HT, hT, np.int32(prob.L),
                        widths[0], widths[1], np.float64(prob.eps_min))


def stack(items):
    """Stack NamedTuples of arrays along a new leading batch axis."""
    return type(items[0])(*[np.stack([np.asarray(getattr(it, f)) for it in items]) for f in items[0]._fields])


def _c2_residual(H, h, sZ, p, eps):
    """``(h - H p - sigma eps) / |H|`` for facets ``H (f, n)``; ``p (..., n)``, ``eps (...)`` ->
    ``(..., f)`` (each row per unit of its state-space normal)."""
    return (h - p @ H.T - sZ * eps[..., None]) / jnp.sqrt(jnp.sum(H * H, axis=1))


def lagrangian(z, Hz, hz, g: PairGeometry, s: MarginSolution, sa: SystemArrays):
    """The ``Z``-dependent part of the Lagrangian of one margin LP at a fixed primal-dual point.

    Its gradient with respect to ``(z, Hz, hz)`` (and through them the parameters of ``Z``)
    is ``dt*/dZ`` (module docstring). ``z (n_v, n)``, ``Hz (f_z, n)``, ``hz (f_z,)``; ``g`` and
    ``s`` one unbatched instance (``vmap`` for a batch). Returns a scalar.
    """
    A, B = jnp.asarray(sa.A), jnp.asarray(sa.B)
    Lp = s.eps.shape[0]
    L = g.L
    sS = jnp.max(g.HS @ z.T, axis=1)                                      # sigma_Z(H_S), (f_s,)
    sT = jnp.max(g.HT @ z.T, axis=1)
    # C2: l = 1 .. L_pad - 1 use p_l = p[l-1]; dual y2[l-1] (zero for l >= L and for l = L_pad)
    r2 = _c2_residual(g.HS, g.hS, sS, s.p, s.eps)                         # (L_pad, f_s)
    pL = jnp.take(s.p, L - 1, axis=0)
    r3 = _c2_residual(g.HT, g.hT, sT, pL, jnp.take(s.eps, L - 1))
    # C4, l = 0 .. L_pad - 1
    HzA, HzB = Hz @ A, Hz @ B                                              # (f_z, n), (f_z, m)
    sw = _sigma_w(sa, Hz)                                                  # (f_z,)
    nH = jnp.sum(Hz * Hz, 1)
    zA = z @ HzA.T                                                         # (n_v, f_z): H_f A z_k
    Bu = jnp.einsum("lkm,fm->lkf", s.u, HzB)                               # (L_pad, n_v, f_z)
    nxt = -(s.p @ Hz.T)[:, None, :] - s.eps[:, None, None] * hz            # -H p_{l+1} - h eps_{l+1}
    first = (g.V @ HzA.T)                                                  # H_f A v_k, (n_v, f_z)
    normal = jnp.sqrt(nH)                                                  # (f_z,): |H_f|, the state-space normal
    r4_0 = (-sw - first - Bu[0] - nxt[0]) / normal
    prev = (s.p[:-1] @ HzA.T)[:, None, :] + s.eps[:-1, None, None] * zA    # l = 1 .. L_pad-1
    r4_l = (-sw - prev - Bu[1:] - nxt[1:]) / normal
    r4 = jnp.concatenate([r4_0[None], r4_l], axis=0)
    # eps bounds
    wZ = jnp.max(z, axis=0) - jnp.min(z, axis=0)
    e_lo = jnp.maximum(g.eps_min, jnp.max(jnp.asarray(sa.w_W) / wZ))
    hiS = jnp.maximum(jnp.min(g.wS / wZ), g.eps_min)
    hiT = jnp.maximum(jnp.min(g.wT / wZ), g.eps_min)
    at_L = jnp.arange(1, Lp + 1) == L
    ub = jnp.where(at_L, hiT, hiS)
    lb = jnp.minimum(e_lo, ub)
    bound = jnp.where(s.d_eps < 0, ub, lb)
    return (jnp.sum(s.y2 * r2) + jnp.sum(s.y3 * r3) + jnp.sum(s.y4 * r4) - jnp.sum(s.d_eps * bound))
