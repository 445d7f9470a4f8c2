"""The generic pieces of each LP's form on the batched PDHG engine, derived from its operator.

Nothing here is written per method: an LP's :class:`~tubejax.lp.declarations.formulation.PdhgForm`
(``Formulation.pdhg``, ``RadiusForm.pdhg``) derives the flat operator, the feasible start, the host
re-check of the certificates and the radius form's start from its operator (:func:`flat_ops`,
:func:`margin_start`, :func:`host_flat_certificates`, :func:`radius_start`).
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import numpy as np

from ..declarations.radius_disturbance import rho_max_bound, unit_disturbance
from .certify import host_certificates, make_margin_certify
from .objective_bounds import ObjectiveRef
from .pdhg import PdhgProblem, ScalingOperator, pdhg_init

__all__ = ["flat_ops", "margin_start", "objective_column", "host_flat_certificates", "RadiusGroup", "radius_start"]


def margin_start(op: tuple, packs: tuple, shape, data, rows_with_t: int | None = None, t_max: float = 1.0):
    """The margin-form :class:`PdhgProblem` on flat ``(n, B)`` vectors (batch axis last) and a feasible start.

    ``op = (matvec, rhs, bounds)`` as in :func:`~.certify.host_certificates`, ``packs = (pack_x,
    pack_y)``. The start is the box centre with ``t`` its margin over the first ``rows_with_t`` row
    blocks (all by default; the rows with a ``t`` column), capped by ``t_max`` (the dense LP's);
    ``t``'s lower bound lies below it. The problem holds ``data.lean()``: only what ``K`` reads goes
    to the device.
    """
    (matvec, rhs, bounds), (px, py) = op, packs
    g, mask = rhs(shape, data, np)
    lo, hi = bounds(shape, data, np)
    B = lo.t.shape[-1]
    zero = np.zeros((B,))
    x_mid = jax.tree_util.tree_map(lambda a, b: 0.5 * (a + b), lo._replace(t=zero), hi._replace(t=zero))
    kx = matvec(shape, data, x_mid, np)
    blocks = list(zip(*map(jax.tree_util.tree_leaves, (g, kx, mask))))[:rows_with_t]
    t0 = np.min(np.stack([np.min(np.where(m > 0, gi - k, np.inf).reshape(-1, B), axis=0, initial=np.inf)
                          for gi, k, m in blocks]), axis=0)                       # t* >= t0
    c, lo, hi, z0 = objective_column(px(lo), px(hi), px(x_mid), np.minimum(t0, 0.0) - 1.0, np.full((B,), t_max),
                                     np.minimum(t0, t_max))
    return PdhgProblem(data.lean(), c, py(g), lo, hi, py(mask)), z0


def objective_column(lo, hi, z0, t_lo, t_hi, t0) -> tuple:
    """``(c, lo, hi, z0)`` of ``max t`` over flat ``(n_x + 1, B)`` vectors whose last row is ``t``
    (the margin, or the radius ``rho``): ``t``'s bounds ``t_lo``, ``t_hi`` and start ``t0`` set, copies."""
    lo, hi, z0, c = lo.copy(), hi.copy(), z0.copy(), np.zeros_like(lo)
    lo[-1], hi[-1], z0[-1], c[-1] = t_lo, t_hi, t0, -1.0
    return c, lo, hi, z0


def flat_ops(shape, xp, matvec, rmatvec, pack_x, unpack_x, pack_y, unpack_y):
    """``matvec``, ``rmatvec`` and the margin certificates on flat ``(n, B)`` vectors, for any
    operator given as ``matvec(shape, d, X, xp)``, ``rmatvec(shape, d, Y, xp)`` on pytrees: a flat
    state makes XLA emit far fewer kernels (faster compiles and iterations)."""
    def mv(d, z):
        return pack_y(matvec(shape, d, unpack_x(shape, z, xp), xp), xp)

    def rmv(d, y):
        return pack_x(rmatvec(shape, d, unpack_y(shape, y, xp), xp), xp)

    cert = make_margin_certify(lambda d, z: matvec(shape, d, z, xp),
                               lambda d, y: rmatvec(shape, d, y, xp), xp)

    def certify(p, z, y):
        ux, uy = (lambda v: unpack_x(shape, v, xp)), (lambda v: unpack_y(shape, v, xp))
        return cert(PdhgProblem(p.data, ux(p.c), uy(p.g), ux(p.lo), ux(p.hi), uy(p.mask)), ux(z), uy(y))

    return mv, rmv, certify


def host_flat_certificates(op: tuple, unpack: tuple, shape, data, z, y) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~tubejax.lp.engines.certify.host_certificates` of ``op = (matvec, rmatvec, rhs, bounds)`` at flat
    points ``z (n_x + 1, B)``, ``y (n_rows, B)``, unpacked by ``unpack = (unpack_x, unpack_y)``; the data and the
    points in float64 (what the engine trusts)."""
    data = jax.tree_util.tree_map(lambda a: np.asarray(a, float), data)
    z, y = unpack[0](shape, np.asarray(z, float)), unpack[1](shape, np.asarray(y, float))
    return host_certificates(op, shape, data, z, y)


class RadiusGroup(NamedTuple):
    """One group of a radius form: its flat host problem at ``rho = 0`` (batch axis last) and what scales it.

    Attributes
    ----------
    data : the operator's host data (its ``lean()`` copy goes to the device)
    g, mask : ``(n_rows, B)``: right-hand sides and row mask
    lo, hi : ``(n_x + 1, B)``: bounds (``rho``'s, the last, are set by :func:`radius_start`)
    x_ref : ``(n_x + 1, B)``: the reference point (the record's ``RadiusForm.reference``)
    mv : the flat matvec     scale_ops : ``(matvec, rmatvec)`` on ``abs_data`` / ``sq_data``
    abs_data, sq_data : ``|K|`` and ``K o K`` data (the scaling's)
    """

    data: object
    g: np.ndarray
    mask: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    x_ref: np.ndarray
    mv: Callable
    scale_ops: tuple
    abs_data: object
    sq_data: object


def _reference(mv, data, g, mask, x_ref):
    """The flat :class:`~tubejax.lp.engines.objective_bounds.ObjectiveRef` of ``x_ref`` (``(n_x + 1, B)``)
    and the largest ``rho`` at which ``x_ref`` satisfies every row with a ``rho`` coefficient, ``(B,)``."""
    col = mv(data, np.zeros_like(x_ref) + np.eye(x_ref.shape[0])[:, -1:])     # rho's column
    rows = mv(data, x_ref) - g
    soft = (mask > 0) & (col > 0)
    rho_ref = np.min(np.where(soft, -rows / np.where(soft, col, 1.0), np.inf), axis=0)
    return ObjectiveRef(x_ref, col, rows), rho_ref


def radius_start(group: RadiusGroup, options, probs) -> tuple:
    """``(host_problem, device_problem, state)`` of ``group``: the state scaled with its ``scale_ops`` on
    ``|K|`` / ``K o K`` data, started at ``x_ref`` with ``rho = rho_ref``. ``rho``'s bounds: ``rho_max``
    (:func:`rho_max_bound` of the target) and ``rho_min = min(rho_ref, 0) - rho_max``, as in
    :func:`~tubejax.lp.evidence.radius_lp.build_radius_lp`."""
    g, mask, x_ref = np.ascontiguousarray(group.g), np.ascontiguousarray(group.mask), group.x_ref
    ref, rho_ref = _reference(group.mv, group.data, g, mask, x_ref)
    W0 = unit_disturbance(probs[0].system.W)[0]
    hi_t = np.array([rho_max_bound(p.target, W0) for p in probs])
    lo_t = np.minimum(rho_ref, 0.0) - hi_t
    c, lo, hi, z0 = objective_column(group.lo, group.hi, x_ref, lo_t, hi_t, np.clip(rho_ref, lo_t, hi_t))
    host = PdhgProblem(group.data, c, g, lo, hi, mask, ref)
    state = pdhg_init(ScalingOperator(*group.scale_ops, group.abs_data, group.sq_data), host, z0, options, np)
    return host, host._replace(data=group.data.lean()), state
