"""The generic pieces of each LP's form on the batched PDHG engine, derived from its operator.

Nothing here is written per method: the engine derives an LP's
:class:`~tubejax.lp.declarations.formulation.PdhgForm` (``Formulation.pdhg``, ``RadiusForm.pdhg``) --
the flat operator, the diagonal scaling, the feasible start, the host re-check of the certificates and
the radius form's start -- from its operator's
:class:`~tubejax.lp.declarations.margin_operator.MarginOperator` (:func:`pdhg_setup`, :func:`flat_ops`,
:func:`scaling_operator`, :func:`margin_start`, :func:`host_flat_certificates`).
"""

from __future__ import annotations

import jax
import numpy as np

from ..declarations.formulation import PdhgForm
from ..declarations.margin_operator import MarginOperator, pack
from ..declarations.radius_disturbance import rho_max_bound, unit_disturbance
from .certify import host_certificates, make_margin_certify
from .objective_bounds import ObjectiveRef
from .pdhg import PdhgProblem, ScalingOperator, pdhg_init

__all__ = ["pdhg_setup", "flat_ops", "scaling_operator", "margin_start", "objective_column",
           "host_flat_certificates"]


def flat_ops(op: MarginOperator, shape, xp):
    """``matvec``, ``rmatvec`` and the margin certificates of ``op`` on flat ``(n, B)`` vectors (its
    ``matvec``, ``rmatvec`` act on pytrees): a flat state makes XLA emit far fewer kernels (faster
    compiles and iterations)."""
    def mv(d, z):
        return pack(op.matvec(shape, d, op.unpack_x(shape, z, xp), xp), xp)

    def rmv(d, y):
        return pack(op.rmatvec(shape, d, op.unpack_y(shape, y, xp), xp), xp)

    cert = make_margin_certify(lambda d, z: op.matvec(shape, d, z, xp),
                               lambda d, y: op.rmatvec(shape, d, y, xp), xp)

    def certify(p, z, y):
        ux, uy = (lambda v: op.unpack_x(shape, v, xp)), (lambda v: op.unpack_y(shape, v, xp))
        return cert(PdhgProblem(p.data, ux(p.c), uy(p.g), ux(p.lo), ux(p.hi), uy(p.mask)), ux(z), uy(y))

    return mv, rmv, certify


def scaling_operator(op: MarginOperator, shape, data) -> ScalingOperator:
    """``K`` as the host's diagonal scaling reads it: ``op.scaling``'s flat operator and coefficients
    (without one, :func:`flat_ops` on ``data``), ``|K|`` and ``K o K`` by ``np.abs`` and ``np.square``."""
    (mv, rmv), coef = (flat_ops(op, shape, np)[:2], data) if op.scaling is None else op.scaling(shape, data)
    return ScalingOperator(mv, rmv, coef.map_coefficients(np.abs), coef.map_coefficients(np.square))


def margin_start(op: MarginOperator, shape, data, t_max: float = 1.0):
    """The margin-form :class:`PdhgProblem` of ``op`` on flat ``(n, B)`` vectors (batch axis last) and a
    feasible start.

    The start is the box centre with ``t`` its margin over the first ``op.rows_with_t`` row blocks (the
    rows with a ``t`` column), capped by ``t_max`` (the dense LP's); ``t``'s lower bound lies below it.
    The problem holds ``data.lean()``: only what ``K`` reads goes to the device.
    """
    g, mask = op.rhs(shape, data, np)
    lo, hi = op.bounds(shape, data, np)
    B = lo.t.shape[-1]
    zero = np.zeros((B,))
    x_mid = jax.tree_util.tree_map(lambda a, b: 0.5 * (a + b), lo._replace(t=zero), hi._replace(t=zero))
    kx = op.matvec(shape, data, x_mid, np)
    blocks = list(zip(*map(jax.tree_util.tree_leaves, (g, kx, mask))))[:op.rows_with_t]
    t0 = np.min(np.stack([np.min(np.where(m > 0, gi - k, np.inf).reshape(-1, B), axis=0, initial=np.inf)
                          for gi, k, m in blocks]), axis=0)                       # t* >= t0
    c, lo, hi, z0 = objective_column(pack(lo), pack(hi), pack(x_mid), np.minimum(t0, 0.0) - 1.0,
                                     np.full((B,), t_max), np.minimum(t0, t_max))
    return PdhgProblem(data.lean(), c, pack(g), lo, hi, pack(mask)), z0


def objective_column(lo, hi, z0, t_lo, t_hi, t0) -> tuple:
    """``(c, lo, hi, z0)`` of ``max t`` over flat ``(n_x + 1, B)`` vectors whose last row is ``t``
    (the margin, or the radius ``rho``): ``t``'s bounds ``t_lo``, ``t_hi`` and start ``t0`` set, copies."""
    lo, hi, z0, c = lo.copy(), hi.copy(), z0.copy(), np.zeros_like(lo)
    lo[-1], hi[-1], z0[-1], c[-1] = t_lo, t_hi, t0, -1.0
    return c, lo, hi, z0


def host_flat_certificates(op: MarginOperator, shape, data, z, y) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~tubejax.lp.engines.certify.host_certificates` of ``op`` at flat points ``z (n_x + 1, B)``,
    ``y (n_rows, B)``; the data and the points in float64 (what the engine trusts)."""
    data = jax.tree_util.tree_map(lambda a: np.asarray(a, float), data)
    z, y = op.unpack_x(shape, np.asarray(z, float)), op.unpack_y(shape, np.asarray(y, float))
    return host_certificates(op, shape, data, z, y)


def _reference(mv, data, g, mask, x_ref):
    """The flat :class:`~tubejax.lp.engines.objective_bounds.ObjectiveRef` of ``x_ref`` (``(n_x + 1, B)``)
    and the largest ``rho`` at which ``x_ref`` satisfies every row with a ``rho`` coefficient, ``(B,)``."""
    col = mv(data, np.zeros_like(x_ref) + np.eye(x_ref.shape[0])[:, -1:])     # rho's column
    rows = mv(data, x_ref) - g
    soft = (mask > 0) & (col > 0)
    rho_ref = np.min(np.where(soft, -rows / np.where(soft, col, 1.0), np.inf), axis=0)
    return ObjectiveRef(x_ref, col, rows), rho_ref


def pdhg_setup(form: PdhgForm, probs, L_pad: int, f_pad: tuple, options, share: bool = True) -> tuple:
    """``(shape, data, prob, state)`` of one group of ``form`` (``B`` problems sharing its ``group_key``):
    its ``data`` at the padded horizon ``L_pad`` and facet counts ``f_pad``, ``prob`` the flat
    :class:`PdhgProblem` (``(n, B)`` vectors, batch axis last) and ``state`` the initial
    :class:`~tubejax.lp.engines.pdhg.PdhgState`, scaled on the host (:func:`scaling_operator`).

    A margin form starts at :func:`margin_start` (``state_dim = shape.n`` with ``form.ruiz``, as in
    :func:`~tubejax.lp.engines.pdhg.pdhg_init`). A radius form has ``data`` at ``rho = 0`` and starts at
    its reference point ``form.radius(shape, probs)`` (a primal pytree) with ``rho = rho_ref``; ``rho``'s
    bounds: ``rho_max`` (:func:`rho_max_bound` of the target) and ``rho_min = min(rho_ref, 0) - rho_max``,
    as in :func:`~tubejax.lp.evidence.radius_lp.build_radius_lp`; then ``data`` is the unscaled host
    :class:`PdhgProblem` and ``prob`` holds ``data.lean()``.
    """
    op = form.operator
    if form.radius is None:
        shape, data = form.data(probs, L_pad, f_pad, share, None)
        prob, z0 = margin_start(op, shape, data)
        state = pdhg_init(scaling_operator(op, shape, data), prob, z0, options, np,
                          state_dim=shape.n if form.ruiz else None)
        return shape, data, prob, state
    W0 = unit_disturbance(probs[0].system.W)[0]
    shape, data = form.data(probs, L_pad, f_pad, share, W0)
    g, mask = op.rhs(shape, data, np)
    lo, hi = op.bounds(shape, data, np)
    g, mask, x_ref = np.ascontiguousarray(pack(g)), np.ascontiguousarray(pack(mask)), pack(form.radius(shape, probs))
    ref, rho_ref = _reference(flat_ops(op, shape, np)[0], data, g, mask, x_ref)
    hi_t = np.array([rho_max_bound(p.target, W0) for p in probs])
    lo_t = np.minimum(rho_ref, 0.0) - hi_t
    c, lo, hi, z0 = objective_column(pack(lo), pack(hi), x_ref, lo_t, hi_t, np.clip(rho_ref, lo_t, hi_t))
    host = PdhgProblem(data, c, g, lo, hi, mask, ref)
    state = pdhg_init(scaling_operator(op, shape, data), host, z0, options, np)
    return shape, host, host._replace(data=data.lean()), state
