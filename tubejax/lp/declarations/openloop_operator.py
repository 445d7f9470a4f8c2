"""Matrix-free margin-form operator ``K``, ``K^T`` of the open-loop LP (docs/math/open-loop.md).

One instance is :func:`~tubejax.lp.declarations.openloop_lp.build_openloop_lp` with ``z = (u, t)``
(``u`` laid out as :class:`~tubejax.lp.declarations.openloop_lp.OpenLoopIndex`, ``t`` last), rows in
its order: C2, C3 (``H[f] . w_k(l) / ||H[f]|| + t <= g``) and the hard input rows without ``t``
(:class:`~.margin_operator.InputBlock`, as the tube's); a zero row is kept only where it binds.
``A^s B`` is a compile-time constant of the group (:attr:`~.margin_operator.OperatorShape.ab`);
:class:`OpenLoopData` holds the per-instance rows (host-only parts in :class:`OpenLoopCoef`); padded
rows carry mask 0. On the device ``K^T`` is ``jax.linear_transpose`` of ``K``
(:func:`openloop_rmatvec_derived`), on the host the fused :func:`openloop_rmatvec`
(:func:`openloop_transpose` picks). In the *radius* form (docs/math/radius.md) ``t`` is ``rho`` and
its column is ``sigma_{D_l}`` of the normalised row for ``W_0``. The engines read it as
:data:`OPENLOOP_OPERATOR`; what it shares with the tube's is in :mod:`.margin_operator`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .margin_operator import (InputBlock, MarginOperator, OperatorShape, input_rows_matvec, input_rows_rhs, pack,
                              unpack)

__all__ = ["OpenLoopData", "OpenLoopX", "OpenLoopY", "openloop_dims", "openloop_matvec", "openloop_rmatvec",
           "openloop_rmatvec_derived", "openloop_transpose", "openloop_rhs", "transfer_blocks",
           "unpack_x", "unpack_y", "ab_blocks", "OpenLoopCoef", "openloop_coef_data", "openloop_coef_ops",
           "openloop_scaling", "OPENLOOP_OPERATOR"]


class OpenLoopData(NamedTuple):
    """Per-instance data, batch axis ``B`` LAST.

    aS : (L-1, f_s, n, B)   ``H_S[f] / N_S(l, f)`` for ``l = 1..L-1`` (0 for a zero row)
    aT : (f_t, n, B)        ``H_j[f] / N_T(L_b, f)`` at the instance's own horizon ``L_b``
    last_step : (L, B)      one-hot of ``L_b`` (``last_step[l-1] = 1`` iff ``l = L_b``)
    gS : (L-1, n_v, f_s, B) C2 right-hand sides (host only)
    gT : (n_v, f_t, B)      C3 right-hand sides (host only)
    mS : (L-1, n_v, f_s, B) C2 row mask: real facet, ``l < L_b``, not a dropped zero row
    mT : (n_v, f_t, B)      C3 row mask
    x_lower, x_upper : (L n_v m, B)   bounding box of ``U`` for every input (host only)
    within_horizon : (L, B) 1 where ``l < L_b`` (host only: the hard input rows' mask)
    cS : (L-1, f_s, B) or None   radius form: coefficient of ``rho`` in C2 row ``(l, ., f)``
    cT : (f_t, B) or None        radius form: coefficient of ``rho`` in C3 row ``(., f)``
    input_rows : InputBlock or None   the hard input rows (``shape.f_u > 0``; ``g`` host only)
    CS : (L-1, f_s, L, m, B) or None   C2's coefficients written out: that of ``u_k(t)[j]`` in row
                                    ``(l, k, f)``, read off the declaration's dense rows (host only;
                                    :class:`OpenLoopCoef`, for the diagonal scaling)
    CT : (f_t, L, m, B) or None     the same for C3 (host only)
    """

    aS: np.ndarray
    aT: np.ndarray
    last_step: np.ndarray
    gS: np.ndarray
    gT: np.ndarray
    mS: np.ndarray
    mT: np.ndarray
    x_lower: np.ndarray
    x_upper: np.ndarray
    within_horizon: np.ndarray
    cS: np.ndarray | None = None
    cT: np.ndarray | None = None
    input_rows: InputBlock | None = None
    CS: np.ndarray | None = None
    CT: np.ndarray | None = None

    def lean(self) -> "OpenLoopData":
        """The data ``K`` reads: right-hand sides, masks and bounds dropped (they live in the
        PDHG problem's ``g``, ``mask``, ``lo``, ``hi``)."""
        return self._replace(gS=None, gT=None, mS=None, mT=None, x_lower=None, x_upper=None, within_horizon=None,
                             CS=None, CT=None,
                             input_rows=None if self.input_rows is None else self.input_rows._replace(g=None))


class OpenLoopX(NamedTuple):
    """Primal vector of a batch: ``u (L, n_v, m, B)``, ``t (B,)``."""

    u: np.ndarray
    t: np.ndarray


class OpenLoopY(NamedTuple):
    """Row vector of a batch: ``yS (L-1, n_v, f_s, B)`` (C2), ``yT (n_v, f_t, B)`` (C3),
    ``yU (L, n_v, f_u, B)`` (hard input rows; ``None`` without them)."""

    yS: np.ndarray
    yT: np.ndarray
    yU: np.ndarray | None = None


def ab_blocks(shape: OperatorShape) -> np.ndarray:
    """``A^s B`` of the group, shape ``(L, n, m)``."""
    return np.asarray(shape.ab, float).reshape(shape.L, shape.n, shape.m)


def transfer_blocks(shape: OperatorShape) -> np.ndarray:
    """``M[l, t] = A^{l-t} B`` for ``t <= l`` else 0, shape ``(L, L, n, m)``: ``w(l+1) = sum_t M[l, t] u(t)``."""
    ab = ab_blocks(shape)
    L = shape.L
    M = np.zeros((L, L, shape.n, shape.m))
    for l in range(L):
        for t in range(l + 1):
            M[l, t] = ab[l - t]
    return M


def openloop_dims(shape: OperatorShape) -> tuple[int, int]:
    """``(n_x, n_rows)`` of one instance, ``n_x`` without ``t``."""
    return (shape.L * shape.n_v * shape.m,
            (shape.L - 1) * shape.n_v * shape.f_s + shape.n_v * shape.f_t + shape.L * shape.n_v * shape.f_u)


def openloop_matvec(shape: OperatorShape, d: OpenLoopData, x: OpenLoopX, xp=np) -> OpenLoopY:
    """``K x`` for a batch (``t`` included; pass ``t = 0`` for the decision problem).

    No row mask is applied (masked rows are ignored by the solver and the certificates).
    """
    L, n = shape.L, shape.n
    dt = x.u.dtype                                                    # float32 iterations stay float32
    M = transfer_blocks(shape).astype(dt)                                   # (L, L, n, m), shared
    w = xp.einsum("ltnj,tkjb->lknb", M, x.u)                          # w[l] = w_k(l+1)
    tS, tT = (d.cS[:, None] * x.t, d.cT[None] * x.t) if shape.form == "radius" else (x.t, x.t)   # t's column
    rS = xp.zeros(d.aS.shape[:1] + (shape.n_v, shape.f_s) + x.t.shape, dt) + tS
    rT = xp.zeros((shape.n_v, shape.f_t) + x.t.shape, dt) + tT
    wL = xp.sum(d.last_step[:, None, None] * w, axis=0)                     # (nv, n, B): w at the own horizon
    for i in range(n):
        rS = rS + d.aS[:, None, :, i] * w[:L - 1, :, None, i]
        rT = rT + d.aT[None, :, i] * wL[:, None, i]
    rU = input_rows_matvec(d.input_rows, x.u) if shape.f_u else None     # hard input rows: no t
    return OpenLoopY(rS, rT, rU)


def openloop_rmatvec(shape: OperatorShape, d: OpenLoopData, y: OpenLoopY, xp=np) -> OpenLoopX:
    """``K^T y`` for a batch, written out (NumPy on the host; equal to :func:`openloop_rmatvec_derived`)."""
    n = shape.n
    M = transfer_blocks(shape)
    cS = xp.stack([xp.sum(d.aS[:, None, :, i] * y.yS, axis=2) for i in range(n)], axis=2)  # (L-1, nv, n, B)
    cT = xp.stack([xp.sum(d.aT[None, :, i] * y.yT, axis=1) for i in range(n)], axis=1)     # (nv, n, B)
    z = xp.zeros((1,) + cT.shape)
    gw = xp.concatenate([cS, z], axis=0) + d.last_step[:, None, None] * cT[None]                 # (L, nv, n, B)
    gu = xp.einsum("ltnj,lknb->tkjb", M, gw)
    if shape.f_u:                                                     # hard input rows act on u only
        gu = gu + xp.einsum("fjb,tkfb->tkjb", d.input_rows.H, y.yU)
    if shape.form == "radius":
        gt = xp.sum(d.cS[:, None] * y.yS, axis=(0, 1, 2)) + xp.sum(d.cT[None] * y.yT, axis=(0, 1))
    else:
        gt = xp.sum(y.yS, axis=(0, 1, 2)) + xp.sum(y.yT, axis=(0, 1))
    return OpenLoopX(gu, gt)


def openloop_rmatvec_derived(shape: OperatorShape, d: OpenLoopData, y: OpenLoopY, xp=None) -> OpenLoopX:
    """``K^T y`` for a batch of JAX arrays: ``jax.linear_transpose`` of :func:`openloop_matvec`."""
    B = y.yT.shape[-1]
    x0 = OpenLoopX(jnp.zeros((shape.L, shape.n_v, shape.m, B), y.yT.dtype), jnp.zeros((B,), y.yT.dtype))
    (gx,) = jax.linear_transpose(lambda x: openloop_matvec(shape, d, x, jnp), x0)(y)
    return gx


def openloop_transpose(shape: OperatorShape, d: OpenLoopData, y: OpenLoopY, xp=np) -> OpenLoopX:
    """``K^T y`` in the array module ``xp``: the fused :func:`openloop_rmatvec` in NumPy (the host's),
    the derived :func:`openloop_rmatvec_derived` in JAX (the device's)."""
    return (openloop_rmatvec if xp is np else openloop_rmatvec_derived)(shape, d, y, xp)


def openloop_rhs(shape: OperatorShape, d: OpenLoopData, xp=np) -> tuple[OpenLoopY, OpenLoopY]:
    """Row right-hand sides ``g`` and row mask (1 = real row), as :class:`OpenLoopY`."""
    gU, mU = input_rows_rhs(d.input_rows, d.within_horizon, shape.n_v, xp) if shape.f_u else (None, None)
    return OpenLoopY(d.gS, d.gT, gU), OpenLoopY(d.mS, d.mT, mU)


def unpack_x(shape: OperatorShape, z, xp=np) -> OpenLoopX:
    """Flat ``(n_x + 1, B)`` (``build_openloop_lp`` layout, ``t`` last) -> :class:`OpenLoopX`."""
    return OpenLoopX(*unpack(z, [(shape.L, shape.n_v, shape.m), ()]))


def unpack_y(shape: OperatorShape, y, xp=np) -> OpenLoopY:
    """Flat ``(n_rows, B)`` (``build_openloop_lp`` row order, padded) -> :class:`OpenLoopY`."""
    L, nv = shape.L, shape.n_v
    return OpenLoopY(*unpack(y, [(L - 1, nv, shape.f_s), (nv, shape.f_t), (L, nv, shape.f_u) if shape.f_u else None]))


class OpenLoopCoef(NamedTuple):
    """``K`` as explicit per-instance coefficients (host only): ``|K|`` and ``K o K`` of the diagonal
    scaling are :func:`numpy.abs` and squares of them (:meth:`map_coefficients`). They are the dense rows the
    families derive, read off per vertex block (``OpenLoopData.CS``, ``CT``), not written here.

    CS : (L-1, f_s, L, m, B)  coefficient of ``u_k(t)[j]`` in C2 row ``(l, k, f)``
    CT : (f_t, L, m, B)       the same for C3
    mS, mT : row masks (dropped rows get no coefficient, not even ``t``'s)
    tS : (L-1, f_s, B) or (1, 1, 1)   ``t``'s coefficient in C2 rows (1 in the margin form)
    tT : (f_t, B) or (1, 1)           ``t``'s coefficient in C3 rows
    CU : (f_u, m, B) or None          coefficient of ``u_k(l)[j]`` in hard input row ``(l, k, f)``
    mU : (L, n_v, f_u, B) or None     their row mask
    """

    CS: np.ndarray
    CT: np.ndarray
    mS: np.ndarray
    mT: np.ndarray
    tS: np.ndarray
    tT: np.ndarray
    CU: np.ndarray | None = None
    mU: np.ndarray | None = None

    def map_coefficients(self, fn) -> "OpenLoopCoef":
        """The coefficients mapped by ``fn`` (masks unchanged): ``np.abs`` gives ``|K|``,
        squaring ``K o K``."""
        return self._replace(CS=fn(self.CS), CT=fn(self.CT), tS=fn(self.tS), tT=fn(self.tT),
                             CU=None if self.CU is None else fn(self.CU))


def openloop_coef_data(shape: OperatorShape, d: OpenLoopData) -> OpenLoopCoef:
    """The operator of ``d`` as explicit coefficients (``|K|`` = :func:`numpy.abs` of them).

    Raises
    ------
    ValueError
        When ``d`` has no coefficients (``d.lean()``: the device copy).
    """
    if d.CS is None or d.CT is None:
        raise ValueError("OpenLoopData without its coefficients CS, CT (a lean() copy): build it with "
                         "build_openloop_data")
    CU, mU = (d.input_rows.H, openloop_rhs(shape, d)[1].yU) if shape.f_u else (None, None)
    tS, tT = (d.cS, d.cT) if shape.form == "radius" else (np.ones((1, 1, 1)), np.ones((1, 1)))
    return OpenLoopCoef(d.CS, d.CT, d.mS, d.mT, tS, tT, CU, mU)


def openloop_coef_ops(shape: OperatorShape):
    """``matvec``, ``rmatvec`` on flat vectors with :class:`OpenLoopCoef` data (NumPy, host).

    With ``coef.map_coefficients(np.abs)`` they apply ``|K|``, with ``np.square`` ``K o K``
    (the ``t`` column is ``tS``, ``tT`` on real rows, 0 on masked ones and on the hard input rows).
    """
    def mv(c: OpenLoopCoef, z):
        x = unpack_x(shape, z)
        rS = (np.einsum("lftjb,tkjb->lkfb", c.CS, x.u) + c.tS[:, None] * x.t) * c.mS
        rT = (np.einsum("ftjb,tkjb->kfb", c.CT, x.u) + c.tT[None] * x.t) * c.mT
        rU = None if c.CU is None else np.einsum("fjb,tkjb->tkfb", c.CU, x.u) * c.mU
        return pack(OpenLoopY(rS, rT, rU))

    def rmv(c: OpenLoopCoef, yv):
        y = unpack_y(shape, yv)
        yS, yT = y.yS * c.mS, y.yT * c.mT
        gu = np.einsum("lftjb,lkfb->tkjb", c.CS, yS) + np.einsum("ftjb,kfb->tkjb", c.CT, yT)
        if c.CU is not None:
            gu = gu + np.einsum("fjb,tkfb->tkjb", c.CU, y.yU * c.mU)
        gt = np.sum(c.tS[:, None] * yS, axis=(0, 1, 2)) + np.sum(c.tT[None] * yT, axis=(0, 1))
        return pack(OpenLoopX(gu, gt))

    return mv, rmv


def openloop_scaling(shape: OperatorShape, d: OpenLoopData) -> tuple:
    """``((matvec, rmatvec), coefficients)`` of the diagonal scaling: ``K`` composes ``A^s B`` with the
    rows, so ``|K|`` is not the operator on ``|d|``; it is :func:`openloop_coef_ops` on
    ``openloop_coef_data(shape, d).map_coefficients(np.abs)``."""
    return openloop_coef_ops(shape), openloop_coef_data(shape, d)


#: The open-loop LP's matrix-free operator: C2 and C3 rows have ``t``'s column, the hard input rows not.
OPENLOOP_OPERATOR = MarginOperator(openloop_matvec, openloop_transpose, openloop_rhs, unpack_x, unpack_y,
                                   scaling=openloop_scaling, rows_with_t=2)
