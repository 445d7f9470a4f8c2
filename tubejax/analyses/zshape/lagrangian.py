"""The margin ``t*(Z)`` of the tube LP as a function of ``Z``, and its envelope-theorem gradient
(docs/math/margins.md#gradient-in-z).

:func:`lagrangian` evaluates the margin families of
:data:`~tubejax.lp.declarations.tube_families.TUBE_FAMILIES` on JAX arrays (no row is written here),
each ``VertexIn`` family at every step (zero duals where it has no rows). Arrays are padded to a
horizon ``L_pad`` and a facet count per region (padding with zero duals), so one compiled function
serves every instance.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ...lp.declarations.tube_families import (TUBE_FAMILIES, TubeTerms, TubeVars, VertexIn, implied_eps_bounds,
                                               region_sets)
from ...lp.declarations.row_families import SetRows, active, step_indices
from ...lp.declarations.tube_variables import axis_widths, within_box
from ...lp.declarations.tube_operator_data import vertex_families
from ...model.geometry import Ball

__all__ = ["PairGeometry", "MarginSolution", "SystemArrays", "system_arrays", "pair_geometry", "facet_counts", "margin_families",
           "dual_shape", "padded_duals", "lagrangian", "stack"]


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
    W = system.W
    if isinstance(W, Ball):
        return SystemArrays(system.A, system.B, np.float64(W.radius), np.zeros((1, system.n)), axis_widths(W))
    return SystemArrays(system.A, system.B, np.float64(-1.0), W.vertices, axis_widths(W))


def _sigma_w(sa: SystemArrays, a):
    """``sigma_W(a)`` for rows ``a`` of shape ``(..., n)``."""
    if float(sa.radius) >= 0:
        return sa.radius * jnp.linalg.norm(a, axis=-1)
    return jnp.max(a @ jnp.asarray(sa.W_vertices).T, axis=-1)


def margin_families(families=TUBE_FAMILIES, regions=None) -> tuple:
    """The families with margin rows, each ``VertexIn`` widened to every step (the form
    :func:`lagrangian` evaluates; its duals are zero at the steps the family does not cover).

    ``regions``: the ``VertexIn`` regions the problems have (e.g. the keys of :attr:`PairGeometry.sets`);
    a family over another region has no rows (:func:`~tubejax.lp.declarations.row_families.active`).
    """
    out = []
    for f in (families if regions is None else active(families, regions)):
        if f.lp_role(None, True) != "margin":
            continue
        out.append(dataclasses.replace(f, steps="all") if isinstance(f, VertexIn) else f)
    return tuple(out)


class PairGeometry(NamedTuple):
    """One ``(pair, L)`` instance without ``Z`` (add a leading batch axis with :func:`stack`).

    Attributes
    ----------
    V : (n_v, n)     source cell vertices ``v_k`` (canonical order)
    sets : dict      per ``VertexIn`` region (``'safe'``: ``S``, ``'target'``: ``P_j``): ``(H (f, n), h (f,))``,
                     padded by repeating facet 0
    L : () int       horizon
    wS, wT : (n,)    axis widths of ``S`` and ``P_j`` (within the pair's box), for the ``eps`` bounds
    eps_min : ()
    """

    V: np.ndarray
    sets: dict
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
    y : dict                     the row duals by family name (:func:`padded_duals`): a ``VertexIn``
                                 family ``(L_pad, f)`` (row ``l - 1`` for step ``l``), ``dynamics``
                                 ``(L_pad, n_v, f_z)``
    d_eps : (L_pad,)             reduced costs of ``eps_1 .. eps_L`` (``min -t``)
    """

    t: np.ndarray
    p: np.ndarray
    eps: np.ndarray
    u: np.ndarray
    y: dict
    d_eps: np.ndarray


def dual_shape(f, L_pad: int, f_pad: dict, per_step: tuple) -> tuple:
    """The shape of the margin family ``f``'s duals in :attr:`MarginSolution.y`: ``(L_pad, f_pad[f.region])`` for a
    ``VertexIn`` family (rows compressed over the vertices; ``f_pad``: the padded facet count per region),
    else ``(L_pad, *per_step)`` (``per_step``: its axes after the step axis, ``(n_v, f_z)`` for ``dynamics``)."""
    return (L_pad, f_pad[f.region]) if isinstance(f, VertexIn) else (L_pad,) + tuple(per_step)


def padded_duals(rows: dict, L: int, L_pad: int, f_pad: dict, families=TUBE_FAMILIES) -> dict:
    """The row duals ``rows`` of a margin LP at horizon ``L`` (``layout.split(y)``: ``{name: (*grid)}``) in the
    padded shapes of :attr:`MarginSolution.y` (``f_pad``: the padded facet count per ``VertexIn`` region)."""
    out = {}
    for f in families:
        if f.name not in rows:
            continue
        r = np.asarray(rows[f.name], float)
        steps = step_indices(f.steps, L) if isinstance(f, VertexIn) else np.arange(L)
        y = np.zeros(dual_shape(f, L_pad, f_pad, r.shape[1:]))
        y[(steps,) + tuple(slice(0, k) for k in r.shape[1:])] = r
        out[f.name] = y
    return out


def _pad_rows(H, h, f):
    k = f - H.shape[0]
    if k < 0:
        raise ValueError(f"cannot pad {H.shape[0]} facets to {f}")
    return np.vstack([H, np.repeat(H[:1], k, axis=0)]), np.concatenate([h, np.repeat(h[:1], k)])


def facet_counts(prob) -> dict:
    """The facet count of each ``VertexIn`` region of ``prob`` (``{'safe': f_s, 'target': f_t}``)."""
    sets = region_sets(prob)
    return {f.region: int(sets[f.region].H.shape[0]) for f in vertex_families(prob.system)}


def pair_geometry(prob, f_pad: dict | None = None) -> PairGeometry:
    """:class:`PairGeometry` of a :class:`~tubejax.model.problem.TubeProblem` (its ``Z`` unused).

    ``f_pad`` gives the padded facet count of each ``VertexIn`` region (default: :func:`facet_counts`).
    The widths are those of the float LP's boxes (:func:`~tubejax.lp.declarations.tube_variables.within_box`).
    """
    blo, bhi = (np.asarray(b, float) for b in prob.box)
    widths = []
    for P in (prob.safe, prob.target):
        lo, hi = within_box(*P.bounding_box(), blo, bhi)
        widths.append(hi - lo)
    given = region_sets(prob)
    sets = {r: _pad_rows(given[r].H, given[r].h, f) for r, f in (f_pad or facet_counts(prob)).items()}
    return PairGeometry(np.asarray(prob.source.vertices, float), sets, np.int32(prob.L),
                        widths[0], widths[1], np.float64(prob.eps_min))


def stack(items):
    """Stack NamedTuples (of arrays and dicts of arrays) along a new leading batch axis."""
    return jax.tree_util.tree_map(lambda *a: np.stack([np.asarray(v) for v in a]), *items)


def lagrangian(z, Hz, hz, g: PairGeometry, s: MarginSolution, sa: SystemArrays, families=TUBE_FAMILIES):
    """The ``Z``-dependent part of the Lagrangian of one margin LP at a fixed primal-dual point:
    ``Σ_rows y_r (slack of row r) - Σ_l d_eps,l (the bound of eps_l that binds)``, over the margin
    families (:func:`margin_families`) per unit of their state-space normal, a compressed family as
    its largest residual over the vertices (the LP's row in value and gradient wherever ``eps >= 0``).
    Its gradient in ``(z, Hz, hz)`` is ``dt*/dZ``. ``z (n_v, n)``, ``Hz (f_z, n)``, ``hz (f_z,)``;
    ``g`` and ``s`` one unbatched instance (``vmap`` for a batch). Returns a scalar."""
    Lp = s.eps.shape[0]
    sets = {r: SetRows(H, h, jnp.linalg.norm(H, axis=1)) for r, (H, h) in g.sets.items()}
    d = TubeTerms(Lp, g.V, z, jnp.asarray(sa.A), jnp.asarray(sa.B), SetRows(Hz, hz, jnp.linalg.norm(Hz, axis=1)),
                  _sigma_w(sa, Hz), sets, jnp.reshape(g.eps_min, (1,)), jnp.concatenate, frozenset(sets))
    x = TubeVars(s.p, s.eps, s.u)
    total = 0.0
    for f in margin_families(families, g.sets):
        r = f.lhs(d, x) - f.rhs(d)                                        # (*grid), <= 0 where the row holds
        if f.compress_vertices:          # eps >= 0 (the LP's bounds): max_k H q_k = H p + sigma_Z(H) eps
            r = jnp.max(r, axis=-2)
        total = total + jnp.sum(s.y[f.name] * (-r / f.scale(d)))
    # the bounds of eps: they depend on Z through its axis widths (module docstring)
    wZ = jnp.max(z, axis=0) - jnp.min(z, axis=0)
    lo, hi = implied_eps_bounds(jnp.stack([g.wS, g.wT]), wZ, jnp.asarray(sa.w_W), g.eps_min, jnp, meet=True)
    last = jnp.arange(1, Lp + 1) == g.L                                   # S's (l < L), P_j's (l = L)
    bound = jnp.where(s.d_eps < 0, jnp.where(last, hi[1], hi[0]), jnp.where(last, lo[1], lo[0]))
    return total - jnp.sum(s.d_eps * bound)
