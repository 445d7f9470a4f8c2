"""Float64 bounds on the optimum of ``max t  s.t.  K (x, t) <= g,  lo <= x <= hi`` when ``t``'s
column is a per-row coefficient ``c >= 0`` (the radius form, docs/math/radius.md), for the
optimise mode of :mod:`tubejax.lp.engines.pdhg`.

The upper bound is rigorous: weak duality (:func:`tubejax.lp.engines.certify.dual_bound`, with
``(K^T y)_t = c^T y``), capped by ``hi_t`` where that cuts off no feasible point. The lower estimate
is a primal point's objective: rows with ``c > 0`` absorb a violation through ``t``; an iterate
violating a row with ``c = 0`` is first moved towards a reference point satisfying them strictly
(:class:`ObjectiveRef`). It is evidence, not a proof: an edge's stored evidence is HiGHS's. With
``c = 1`` the estimate is minus :func:`~tubejax.lp.engines.certify.primal_violation`. Vectors are
pytrees, batch axis last, with a field ``t``; ``xp`` is NumPy or ``jax.numpy``.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import numpy as np

from .certify import FEAS_TOL, _red, _xleaves, dual_bound

__all__ = ["ObjectiveRef", "RowsAndBox", "FlatX", "FlatY", "objective_lower", "make_objective_certify",
           "host_objective_certificates"]

_tm = jax.tree_util.tree_map


class ObjectiveRef(NamedTuple):
    """The reference of the lower estimate, precomputed once per instance on the host.

    x : primal pytree -- the reference point (box-feasible; every row without ``t`` strict)
    col : row pytree  -- ``t``'s column, ``K (0, 1)``
    rows : row pytree -- ``K (x_ref, 0) - g``
    """

    x: Any
    col: Any
    rows: Any


class RowsAndBox(NamedTuple):
    """The constraints a primal point is checked against: ``K (x, t) <= g`` on the rows where
    ``mask > 0`` (``g, mask``: row pytrees) and the box ``lo <= x <= hi`` (primal pytrees with a
    field ``t``; ``hi.t`` caps the objective)."""

    g: Any
    mask: Any
    lo: Any
    hi: Any


def objective_lower(matvec: Callable, data, constraints: RowsAndBox, ref: ObjectiveRef | None, z, xp=np,
                    tol: float = FEAS_TOL):
    """Lower estimate of ``max t`` from the primal point ``z`` (its ``t`` is ignored).

    The rows of the repaired point ``x' = (1 - theta) x + theta x_ref`` are
    ``(1 - theta) (K x - g) + theta (K x_ref - g)`` (``K`` is linear): one ``matvec`` per call.

    Parameters
    ----------
    matvec : ``matvec(data, z) -> rows`` (pytrees, batch axis last)
    constraints : RowsAndBox
        ``g, mask`` (row pytrees) and ``lo, hi`` (primal pytrees with a field ``t``).
    z : primal pytree with a field ``t``
    ref : ObjectiveRef or None
        The reference (see the module docstring); ``None``: ``t``'s column is recomputed
        and ``z`` must satisfy the rows without ``t`` itself (to ``tol``).
    tol : float
        Largest violation of a row without ``t``, or of the box, that is accepted.

    Returns
    -------
    (B,) -- the largest ``t <= hi_t`` feasible with the repaired point; ``-inf`` where no
    repair is possible (``x_ref`` violates a row itself) or anything is not finite
    """
    g, mask, lo, hi = constraints
    zt = xp.zeros_like(z.t)
    x = z._replace(t=zt)
    leaves = jax.tree_util.tree_leaves                       # row pytrees of any nesting
    col = leaves(matvec(data, _tm(xp.zeros_like, x)._replace(t=xp.ones_like(zt))) if ref is None
                 else ref.col)
    mask = leaves(mask)
    hard = [(mi > 0) & (ci == 0) for mi, ci in zip(mask, col)]
    soft = [(mi > 0) & (ci > 0) for mi, ci in zip(mask, col)]
    r = [k - gi for k, gi in zip(leaves(matvec(data, x)), leaves(g))]
    ok = xp.ones(zt.shape, dtype=bool)
    if ref is not None:
        theta = zt
        for ri, qi, hi_ in zip(r, leaves(ref.rows), hard):
            bad = hi_ & (ri > 0)
            fix = bad & (qi < 0)
            step = xp.where(fix, ri / xp.where(fix, ri - qi, 1.0), xp.where(bad, xp.inf, 0.0))
            theta = xp.maximum(theta, _red(xp.max, step, initial=0.0))
        ok = theta <= 1.0
        th = xp.where(ok, theta, 0.0)
        r = [(1.0 - th) * ri + th * qi for ri, qi in zip(r, leaves(ref.rows))]
    lower = zt + xp.inf
    worst = zt - xp.inf
    for ri, ci, si, hi_ in zip(r, col, soft, hard):
        lower = xp.minimum(lower, _red(xp.min, xp.where(si, -ri / xp.where(si, ci, 1.0), xp.inf),
                                       initial=np.inf))
        worst = xp.maximum(worst, _red(xp.max, xp.where(hi_, ri, -xp.inf), initial=-np.inf))
    for zi, li, ui in zip(_xleaves(z), _xleaves(lo), _xleaves(hi)):
        ok = ok & _red(xp.all, xp.isfinite(zi))
        worst = xp.maximum(worst, _red(xp.max, xp.maximum(li - zi, zi - ui), initial=-np.inf))
    ok = ok & (worst <= tol) & xp.isfinite(lower)
    return xp.where(ok, xp.minimum(lower, hi.t), -xp.inf)


class FlatX(NamedTuple):
    """A flat primal vector ``(n_x + 1, B)`` seen as a pytree: ``x (n_x, B)`` and ``t (B,)`` (last row)."""

    x: Any
    t: Any


class FlatY(NamedTuple):
    """A flat row vector ``(n_rows, B)`` seen as a pytree."""

    y: Any


def _fx(z):
    return FlatX(z[:-1], z[-1])


def make_objective_certify(matvec: Callable, rmatvec: Callable, xp):
    """``certify(prob, z, y) -> (-lower, upper)`` on FLAT vectors (``t`` the last row of ``z``) for the
    optimise mode and its host re-check, for any formulation's flat operator
    (:func:`~tubejax.lp.engines.pdhg_adapters.flat_ops`); ``prob.ref`` is a flat :class:`ObjectiveRef` or ``None``. ``lower`` is :func:`objective_lower`,
    ``upper`` :func:`~tubejax.lp.engines.certify.dual_bound` capped by ``hi_t``."""
    def mv(d, X):
        return FlatY(matvec(d, xp.concatenate([X.x, X.t[None]], axis=0)))

    def rmv(d, Y):
        return _fx(rmatvec(d, Y.y))

    def certify(prob, z, y):
        ref = None if prob.ref is None else ObjectiveRef(_fx(prob.ref[0]), FlatY(prob.ref[1]),
                                                         FlatY(prob.ref[2]))
        g, mask, lo, hi = FlatY(prob.g), FlatY(prob.mask), _fx(prob.lo), _fx(prob.hi)
        lower = objective_lower(mv, prob.data, RowsAndBox(g, mask, lo, hi), ref, _fx(z), xp)
        upper = dual_bound(rmv, prob.data, g, mask, lo, hi, FlatY(y), xp)
        return -lower, xp.minimum(upper, hi.t)

    return certify


def host_objective_certificates(ops, shape, prob, z, y) -> tuple[np.ndarray, np.ndarray]:
    """``(-lower, upper)``, each ``(B,)``: the optimise-mode certificate recomputed on the host
    in NumPy float64 from the unscaled flat problem ``prob`` with a formulation's operator
    ``ops(shape, xp)`` (:func:`~tubejax.lp.engines.pdhg_adapters.flat_ops` of a form's operator): what
    :func:`~tubejax.lp.batch.optimise_mode.optimise_batch` reports (the device's own check only decides when
    to stop)."""
    mv, rmv, _ = ops(shape, np)
    certify = make_objective_certify(mv, rmv, np)
    f64 = lambda a: None if a is None else np.asarray(a, np.float64)           # noqa: E731
    prob = prob._replace(ref=None if prob.ref is None else type(prob.ref)(*map(f64, prob.ref)))
    neg_lower, upper = certify(prob, f64(z), f64(y))
    return np.asarray(neg_lower, np.float64), np.asarray(upper, np.float64)
