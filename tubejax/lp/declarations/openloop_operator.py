"""Matrix-free margin-form operator ``K``, ``K^T`` of the open-loop LP (docs/math/open-loop.md).

One instance is :func:`~tubejax.lp.declarations.openloop_lp.build_openloop_lp` with ``z = (u, t)``
(``u`` laid out as :class:`~tubejax.lp.declarations.openloop_lp.OpenLoopIndex`, ``t`` last), rows in
its order: C2, C3 (``H[f] . w_k(l) / ||H[f]|| + t <= g``) and the hard input rows without ``t``
(:func:`~tubejax.lp.declarations.tube_operator_data.input_block`); a zero row is kept only where it
binds. ``A^s B`` is a compile-time constant of the group (:attr:`~.tube_operator.OperatorShape.ab`);
:class:`OpenLoopData` holds the per-instance rows (host-only parts in :class:`OpenLoopCoef`); padded
rows carry mask 0. On the device ``K^T`` is ``jax.linear_transpose`` of ``K``
(:func:`openloop_rmatvec_derived`), on the host the fused :func:`openloop_rmatvec`
(:func:`openloop_transpose` picks). In the *radius* form (docs/math/radius.md) ``t`` is ``rho`` and
its column is ``sigma_{D_l}`` of the normalised row for ``W_0``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .tube_operator import OperatorShape

__all__ = ["OpenLoopData", "OpenLoopX", "OpenLoopY", "openloop_dims", "openloop_matvec",
           "openloop_rmatvec",
           "openloop_rmatvec_derived", "openloop_transpose",
           "openloop_rhs", "openloop_bounds", "transfer_blocks",
           "pack_x", "unpack_x", "pack_y", "unpack_y", "ab_blocks", "OpenLoopCoef",
           "openloop_coef_data", "openloop_coef_ops"]


class OpenLoopData(NamedTuple):
    """Per-instance data, batch axis ``B`` LAST.

    aS : (L-1, f_s, n, B)   ``H_S[f] / N_S(l, f)`` for ``l = 1..L-1`` (0 for a zero row)
    aT : (f_t, n, B)        ``H_j[f] / N_T(L_b, f)`` at the instance's own horizon ``L_b``
    sel : (L, B)            one-hot of ``L_b`` (``sel[l-1] = 1`` iff ``l = L_b``)
    gS : (L-1, n_v, f_s, B) C2 right-hand sides (host only)
    gT : (n_v, f_t, B)      C3 right-hand sides (host only)
    mS : (L-1, n_v, f_s, B) C2 row mask: real facet, ``l < L_b``, not a dropped zero row
    mT : (n_v, f_t, B)      C3 row mask
    lb, ub : (L n_v m, B)   bounding box of ``U`` for every input (host only)
    cS : (L-1, f_s, B) or None   radius form: coefficient of ``rho`` in C2 row ``(l, ., f)``
    cT : (f_t, B) or None        radius form: coefficient of ``rho`` in C3 row ``(., f)``
    Hu : (f_u, m, B) or None     the hard input rows' unit normals (``shape.f_u > 0``)
    gU : (L, n_v, f_u, B) or None   their right-hand sides (host only)
    mU : (L, n_v, f_u, B) or None   their row mask: ``l < L_b`` (host only)
    CS : (L-1, f_s, L, m, B) or None   C2's coefficients written out: that of ``u_k(t)[j]`` in row
                                    ``(l, k, f)``, read off the declaration's dense rows (host only;
                                    :class:`OpenLoopCoef`, for the diagonal scaling)
    CT : (f_t, L, m, B) or None     the same for C3 (host only)
    """

    aS: np.ndarray
    aT: np.ndarray
    sel: np.ndarray
    gS: np.ndarray
    gT: np.ndarray
    mS: np.ndarray
    mT: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    cS: np.ndarray | None = None
    cT: np.ndarray | None = None
    Hu: np.ndarray | None = None
    gU: np.ndarray | None = None
    mU: np.ndarray | None = None
    CS: np.ndarray | None = None
    CT: np.ndarray | None = None

    def lean(self) -> "OpenLoopData":
        """The data ``K`` reads: right-hand sides, masks and bounds dropped (they live in the
        PDHG problem's ``g``, ``mask``, ``lo``, ``hi``)."""
        return self._replace(gS=None, gT=None, mS=None, mT=None, lb=None, ub=None, gU=None, mU=None, CS=None,
                             CT=None)


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
    if shape.form == "radius":
        rS = xp.zeros(d.aS.shape[:1] + (shape.n_v, shape.f_s) + x.t.shape, dt) + d.cS[:, None] * x.t
        rT = xp.zeros((shape.n_v, shape.f_t) + x.t.shape, dt) + d.cT[None] * x.t
    else:
        rS = xp.zeros(d.aS.shape[:1] + (shape.n_v, shape.f_s) + x.t.shape, dt) + x.t
        rT = xp.zeros((shape.n_v, shape.f_t) + x.t.shape, dt) + x.t
    wL = xp.sum(d.sel[:, None, None] * w, axis=0)                     # (nv, n, B): w at the own horizon
    for i in range(n):
        rS = rS + d.aS[:, None, :, i] * w[:L - 1, :, None, i]
        rT = rT + d.aT[None, :, i] * wL[:, None, i]
    rU = None
    if shape.f_u:                                                     # hard input rows: no t
        rU = d.Hu[None, None, :, 0] * x.u[:, :, None, 0]
        for j in range(1, shape.m):
            rU = rU + d.Hu[None, None, :, j] * x.u[:, :, None, j]
    return OpenLoopY(rS, rT, rU)


def openloop_rmatvec(shape: OperatorShape, d: OpenLoopData, y: OpenLoopY, xp=np) -> OpenLoopX:
    """``K^T y`` for a batch, written out (NumPy on the host; equal to :func:`openloop_rmatvec_derived`)."""
    n = shape.n
    M = transfer_blocks(shape)
    cS = xp.stack([xp.sum(d.aS[:, None, :, i] * y.yS, axis=2) for i in range(n)], axis=2)  # (L-1, nv, n, B)
    cT = xp.stack([xp.sum(d.aT[None, :, i] * y.yT, axis=1) for i in range(n)], axis=1)     # (nv, n, B)
    z = xp.zeros((1,) + cT.shape)
    gw = xp.concatenate([cS, z], axis=0) + d.sel[:, None, None] * cT[None]                 # (L, nv, n, B)
    gu = xp.einsum("ltnj,lknb->tkjb", M, gw)
    if shape.f_u:                                                     # hard input rows act on u only
        gu = gu + xp.einsum("fjb,tkfb->tkjb", d.Hu, y.yU)
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


def openloop_transpose(xp):
    """``K^T`` in the array module ``xp``: the derived transpose for JAX, the fused one for NumPy."""
    return openloop_rmatvec if xp is np else openloop_rmatvec_derived


def openloop_rhs(shape: OperatorShape, d: OpenLoopData, xp=np) -> tuple[OpenLoopY, OpenLoopY]:
    """Row right-hand sides ``g`` and row mask (1 = real row), as :class:`OpenLoopY`."""
    return OpenLoopY(d.gS, d.gT, d.gU), OpenLoopY(d.mS, d.mT, d.mU)


def openloop_bounds(shape: OperatorShape, d: OpenLoopData, xp=np) -> tuple[OpenLoopX, OpenLoopX]:
    """Box bounds of ``u`` as :class:`OpenLoopX` (``t`` bounds ``-inf, inf``; set by the caller)."""
    L, nv, m = shape.L, shape.n_v, shape.m
    B = d.lb.shape[-1]
    inf = xp.full((B,), np.inf)
    return (OpenLoopX(d.lb.reshape(L, nv, m, B), -inf), OpenLoopX(d.ub.reshape(L, nv, m, B), inf))


def unpack_x(shape: OperatorShape, z, xp=np) -> OpenLoopX:
    """Flat ``(n_x + 1, B)`` (``build_openloop_lp`` layout, ``t`` last) -> :class:`OpenLoopX`."""
    B = z.shape[-1]
    return OpenLoopX(z[:-1].reshape(shape.L, shape.n_v, shape.m, B), z[-1])


def pack_x(x: OpenLoopX, xp=np):
    """:class:`OpenLoopX` -> flat ``(n_x + 1, B)``."""
    B = x.t.shape[-1]
    return xp.concatenate([x.u.reshape(-1, B), x.t[None]], axis=0)


def unpack_y(shape: OperatorShape, y, xp=np) -> OpenLoopY:
    """Flat ``(n_rows, B)`` (``build_openloop_lp`` row order, padded) -> :class:`OpenLoopY`."""
    L, nv, fs, ft = shape.L, shape.n_v, shape.f_s, shape.f_t
    B = y.shape[-1]
    o = (L - 1) * nv * fs
    e = o + nv * ft
    yU = y[e:e + L * nv * shape.f_u].reshape(L, nv, shape.f_u, B) if shape.f_u else None
    return OpenLoopY(y[:o].reshape(L - 1, nv, fs, B), y[o:e].reshape(nv, ft, B), yU)


def pack_y(y: OpenLoopY, xp=np):
    """:class:`OpenLoopY` -> flat ``(n_rows, B)``."""
    B = y.yT.shape[-1]
    parts = [y.yS.reshape(-1, B), y.yT.reshape(-1, B)] + ([] if y.yU is None else [y.yU.reshape(-1, B)])
    return xp.concatenate(parts, axis=0)


class OpenLoopCoef(NamedTuple):
    """``K`` as explicit per-instance coefficients (host only): ``|K|`` and ``K o K`` of the diagonal
    scaling are :func:`numpy.abs` and squares of them (:meth:`apply`). They are the dense rows the
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

    def apply(self, fn) -> "OpenLoopCoef":
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
    if shape.form == "radius":
        return OpenLoopCoef(d.CS, d.CT, d.mS, d.mT, d.cS, d.cT, d.Hu, d.mU)
    return OpenLoopCoef(d.CS, d.CT, d.mS, d.mT, np.ones((1, 1, 1)), np.ones((1, 1)), d.Hu, d.mU)


def openloop_coef_ops(shape: OperatorShape):
    """``matvec``, ``rmatvec`` on flat vectors with :class:`OpenLoopCoef` data (NumPy, host).

    With ``coef.apply(np.abs)`` they apply ``|K|``, with ``coef.apply(np.square)`` ``K o K``
    (the ``t`` column is ``tS``, ``tT`` on real rows, 0 on masked ones and on the hard input rows).
    """
    def mv(c: OpenLoopCoef, z):
        x = unpack_x(shape, z)
        rS = (np.einsum("lftjb,tkjb->lkfb", c.CS, x.u) + c.tS[:, None] * x.t) * c.mS
        rT = (np.einsum("ftjb,tkjb->kfb", c.CT, x.u) + c.tT[None] * x.t) * c.mT
        rU = None if c.CU is None else np.einsum("fjb,tkjb->tkfb", c.CU, x.u) * c.mU
        return pack_y(OpenLoopY(rS, rT, rU))

    def rmv(c: OpenLoopCoef, yv):
        y = unpack_y(shape, yv)
        yS, yT = y.yS * c.mS, y.yT * c.mT
        gu = np.einsum("lftjb,lkfb->tkjb", c.CS, yS) + np.einsum("ftjb,kfb->tkjb", c.CT, yT)
        if c.CU is not None:
            gu = gu + np.einsum("fjb,tkfb->tkjb", c.CU, y.yU * c.mU)
        gt = np.sum(c.tS[:, None] * yS, axis=(0, 1, 2)) + np.sum(c.tT[None] * yT, axis=(0, 1))
        return pack_x(OpenLoopX(gu, gt))

    return mv, rmv
