"""Float64 certificates for the margin-form LP ``max t  s.t.  K (x, t) <= g,  lo <= x <= hi``
(``t``'s column 1 on every real row, rows unit-normalised), on the unscaled data.

A box-feasible ``x`` with ``max_i (K (x, 0) - g)_i <= 1e-9`` is feasible (HiGHS's tube is still the
one stored). Any ``y >= 0`` with ``s = sum_i y_i > 0`` bounds
``t* <= (g^T y + sum_j max(a_j lo_j, a_j hi_j)) / s``, ``a = -K_x^T y``, rigorously however
inaccurate ``y`` is; below ``-margin_safety`` it proves infeasibility (docs/math/evidence.md#non-edges).
Vectors are pytrees, batch axis last, with a field ``t``; ``xp`` (``numpy`` or ``jax.numpy``) lets
the same formulas run in the jitted solver and, as the check the solver trusts, on the host.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..declarations.margin_operator import tree_leaves

__all__ = ["primal_violation", "dual_bound", "make_margin_certify", "host_certificates", "MARGIN_SAFETY", "FEAS_TOL"]

#: A dual bound below ``-MARGIN_SAFETY`` certifies infeasibility.
MARGIN_SAFETY = 1e-7
#: Largest primal violation (unit rows, ``t = 0``) accepted as feasible.
FEAS_TOL = 1e-9


def _tree_map(fn, tree, other):
    """``fn`` on matching leaves of two pytrees of the same structure (NamedTuples and tuples;
    ``None`` stays ``None``: a row block the instance does not have)."""
    if tree is None:
        return None
    if isinstance(tree, tuple):
        items = [_tree_map(fn, a, b) for a, b in zip(tree, other)]
        return type(tree)(*items) if hasattr(tree, "_fields") else tuple(items)
    return fn(tree, other)


def _red(fn, v, **kw):
    return fn(v, axis=tuple(range(v.ndim - 1)), **kw) if v.ndim > 1 else v


def _xleaves(z):
    """The leaves of a margin-form primal pytree except ``t``."""
    return [v for k, v in zip(z._fields, z) if k != "t"]


def primal_violation(matvec: Callable, data, g, mask, lo, hi, z, xp=np):
    """Largest violation of Problem 2 by ``x``: rows ``(K (x, 0) - g)_i`` and the box on ``x``.

    Parameters
    ----------
    matvec : ``matvec(data, z) -> rows`` (pytrees with the batch axis last)
    g, mask : row pytrees (any nesting)   lo, hi, z : primal pytrees with a field ``t`` (ignored here)

    Returns
    -------
    (B,) -- ``inf`` where ``x`` is not finite
    """
    z0 = z._replace(t=xp.zeros_like(z.t))
    r = matvec(data, z0)
    viol = None
    for ri, gi, mi in zip(tree_leaves(r), tree_leaves(g), tree_leaves(mask)):
        v = _red(xp.max, xp.where(mi > 0, ri - gi, -xp.inf), initial=-np.inf)
        viol = v if viol is None else xp.maximum(viol, v)
    ok = xp.isfinite(z.t)
    for zi, li, hi_ in zip(_xleaves(z), _xleaves(lo), _xleaves(hi)):
        ok = ok & _red(xp.all, xp.isfinite(zi))
        viol = xp.maximum(viol, _red(xp.max, xp.maximum(li - zi, zi - hi_), initial=-np.inf))
    return xp.where(ok, viol, xp.inf)


def dual_bound(rmatvec: Callable, data, g, mask, lo, hi, y, xp=np):
    """Rigorous upper bound on ``t*`` from ``y`` (negative entries are clipped to 0).

    Returns ``(B,)``; ``inf`` where ``(K^T y)_t <= 0`` or anything is not finite.
    """
    y = _tree_map(lambda yi, mi: xp.maximum(xp.where(mi > 0, yi, 0.0), 0.0), y, mask)
    kty = rmatvec(data, y)
    s = kty.t
    num = sum(_red(xp.sum, gi * yi) for gi, yi in zip(tree_leaves(g), tree_leaves(y)))
    for ai, li, hi_ in zip(_xleaves(kty), _xleaves(lo), _xleaves(hi)):
        num = num + _red(xp.sum, xp.maximum(-ai * li, -ai * hi_))
    ok = (s > 1e-300) & xp.isfinite(num) & xp.isfinite(s)
    return xp.where(ok, num / xp.where(ok, s, 1.0), xp.inf)


def make_margin_certify(matvec: Callable, rmatvec: Callable, xp):
    """``certify(prob, z, y) -> (viol, bound)`` for :func:`tubejax.lp.engines.pdhg.pdhg_terminate`."""

    def certify(prob, z, y):
        viol = primal_violation(matvec, prob.data, prob.g, prob.mask, prob.lo, prob.hi, z, xp)
        bound = dual_bound(rmatvec, prob.data, prob.g, prob.mask, prob.lo, prob.hi, y, xp)
        return viol, bound

    return certify


def host_certificates(op: tuple, shape, data, z, y) -> tuple[np.ndarray, np.ndarray]:
    """A formulation's certificates re-checked in NumPy float64 on its unscaled host data.

    Parameters
    ----------
    op : MarginOperator
        The operator's ``matvec``, ``rmatvec`` (``f(shape, data, v, xp)``), ``rhs(shape, data, xp) ->
        (g, mask)`` and ``bounds(shape, data, xp) -> (lo, hi)``
        (:class:`~tubejax.lp.declarations.margin_operator.MarginOperator`)
    shape, data : the group's static shape and host data (batch axis last, ``B``)
    z, y : primal and dual pytrees

    Returns
    -------
    viol, bound : (B,) each -- the largest violation by ``z`` (``t = 0``, rows and box) and the
    rigorous upper bound on ``t*`` given by ``y``
    """
    g, mask = op.rhs(shape, data, np)
    lo, hi = op.bounds(shape, data, np)
    viol = primal_violation(lambda d, v: op.matvec(shape, d, v, np), data, g, mask, lo, hi, z, np)
    bound = dual_bound(lambda d, v: op.rmatvec(shape, d, v, np), data, g, mask, lo, hi, y, np)
    return np.asarray(viol), np.asarray(bound)
