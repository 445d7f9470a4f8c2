"""Matrix-free margin-form operator ``K``, ``K^T`` of the open-loop LP (docs/math/open-loop.md).

One instance is :func:`tubejax.lp.declarations.openloop_lp.build_openloop_lp` in margin form with
``z = (u, t)``, ``u`` of shape ``(L, n_v, m)`` laid out as
:class:`~tubejax.lp.declarations.openloop_lp.OpenLoopIndex` and ``t`` appended last. The rows come in
the order of ``build_openloop_lp``:

* C2: ``(L-1, n_v, f_s)`` -- ``H_S[f] . w_k(l) / N_S(l, f) + t <= g``, ``l = 1..L-1``;
* C3: ``(n_v, f_t)``      -- the same with the target facets at ``l = L``;
* the hard rows of the input family (C5 of a non-box ``U``): ``(L, n_v, f_u)`` --
  ``H_u[r] u_k(l) <= h_u[r]``, unit rows without ``t``, read off the declaration's dense hard rows
  (:func:`~tubejax.lp.declarations.tube_operator_data.input_block`, as the tube operator does),
  appended after C3 as ``build_openloop_lp``'s ``G_hard`` follows its ``G`` (a box ``U`` is the
  variable bounds, ``f_u = 0``),

where ``w_k(l) = sum_{t<l} A^{l-1-t} B u_k(t)`` is the input part of the nominal state
``xbar_k(l)`` (the free part ``A^l v_k`` and the disturbance tightening
``sigma_{D_l}`` live in the right-hand side) and ``N(f) = ||H[f]||`` is the length of the
row's state-space normal, exactly as ``build_openloop_lp`` scales (the margin is a
state-space distance). A row whose ``u``-coefficients vanish (``(sum_{s<l} ||H[f] A^s
B||^2)^{1/2} <= 1e-12``, possible only when ``H A^s B = 0``) is mirrored too: coefficient 0,
and kept (row mask 1) only when its right-hand side is negative.

Data: the matrices ``A^s B`` are **shared** by a group (one system) and enter the
operator as a compile-time constant (:attr:`OpenLoopShape.ab`); the per-instance
data :class:`OpenLoopData` are the normalised facet rows of ``S`` and ``P_j``
(``aS``, ``aT``), the one-hot of the instance's horizon (``sel``; horizons are
padded to a bucket), and -- host only -- the right-hand sides (built from the
source vertices and the ``sigma_D`` offsets), the row masks and the ``u`` box.
The batch axis is LAST everywhere. Padded rows (facets, steps beyond the
instance's horizon, dropped zero rows) carry row mask 0: the solver keeps their
dual at 0 and the certificates ignore them, so ``K`` itself applies no mask.

``K`` is written out explicitly (one ``einsum`` with the shared ``A^s B`` blocks, broadcast
multiply-adds over the tiny facet / state axes). On the device ``K^T`` is derived:
``jax.linear_transpose`` of ``K`` (:func:`openloop_rmatvec_derived`), because the fused
transpose does not win there (``experiments/benchmark.py`` (e): derived / fused 0.98 on the paper
map's 1,560 pairs at ``L = 10``); the fused :func:`openloop_rmatvec`, tested against the derived
one, serves NumPy on the host (:func:`openloop_transpose` picks);
:func:`~.openloop_coefficients.openloop_coef_ops` gives the same operator through explicit per-instance
coefficients ``|K|``-ready (:attr:`OpenLoopData.CS`, ``CT``: the dense rows' vertex blocks), used on
the host for the diagonal scaling only.

**Two forms** share the operator (:attr:`OpenLoopShape.form`, static): the *margin* form
above (``t``'s column is 1 on every row) and the *radius* form (docs/math/radius.md,
:mod:`tubejax.lp.batch.radius`) for ``W = rho W_0``: ``t`` is ``rho``, the right-hand
sides omit ``sigma_{D_l}`` and ``t``'s column is ``sigma_{D_l}`` of the normalised row for
``W_0`` (``cS``, ``cT``; ``None`` in the margin form, whose traced code is unchanged). A zero
row is then ``c rho <= g``: kept when ``g < 0`` or ``c > 0``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np


__all__ = ["OpenLoopShape", "OpenLoopData", "OpenLoopX", "OpenLoopY", "openloop_dims", "openloop_matvec",
           "openloop_rmatvec",
           "openloop_rmatvec_derived", "openloop_transpose",
           "openloop_rhs", "openloop_bounds", "transfer_blocks",
           "pack_x", "unpack_x", "pack_y", "unpack_y", "ab_blocks"]

class OpenLoopShape(NamedTuple):
    """Static shape of a group (hashable; keys the compiled executables).

    ``ab`` is ``A^s B`` for ``s = 0 .. L-1`` flattened to a tuple of floats (shape
    ``(L, n, m)``): the operator's shared data, a compile-time constant. ``f_u``: the row count
    of the hard input family at one step and vertex (0: none, a box ``U`` is variable bounds).
    """

    L: int
    n: int
    m: int
    n_v: int
    f_s: int
    f_t: int
    ab: tuple
    form: str = "margin"
    f_u: int = 0


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
                                    :mod:`~.openloop_coefficients`, for the diagonal scaling)
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



def ab_blocks(shape: OpenLoopShape) -> np.ndarray:
    """``A^s B`` of the group, shape ``(L, n, m)``."""
    return np.asarray(shape.ab, float).reshape(shape.L, shape.n, shape.m)


def transfer_blocks(shape: OpenLoopShape) -> np.ndarray:
    """``M[l, t] = A^{l-t} B`` for ``t <= l`` else 0, shape ``(L, L, n, m)``: ``w(l+1) = sum_t M[l, t] u(t)``."""
    ab = ab_blocks(shape)
    L = shape.L
    M = np.zeros((L, L, shape.n, shape.m))
    for l in range(L):
        for t in range(l + 1):
            M[l, t] = ab[l - t]
    return M


def openloop_dims(shape: OpenLoopShape) -> tuple[int, int]:
    """``(n_x, n_rows)`` of one instance, ``n_x`` without ``t``."""
    return (shape.L * shape.n_v * shape.m,
            (shape.L - 1) * shape.n_v * shape.f_s + shape.n_v * shape.f_t + shape.L * shape.n_v * shape.f_u)


# ----------------------------------------------------------------------------- the operator
def openloop_matvec(shape: OpenLoopShape, d: OpenLoopData, x: OpenLoopX, xp=np) -> OpenLoopY:
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


def openloop_rmatvec(shape: OpenLoopShape, d: OpenLoopData, y: OpenLoopY, xp=np) -> OpenLoopX:
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


def openloop_rmatvec_derived(shape: OpenLoopShape, d: OpenLoopData, y: OpenLoopY, xp=None) -> OpenLoopX:
    """``K^T y`` for a batch of JAX arrays: ``jax.linear_transpose`` of :func:`openloop_matvec`."""
    B = y.yT.shape[-1]
    x0 = OpenLoopX(jnp.zeros((shape.L, shape.n_v, shape.m, B), y.yT.dtype), jnp.zeros((B,), y.yT.dtype))
    (gx,) = jax.linear_transpose(lambda x: openloop_matvec(shape, d, x, jnp), x0)(y)
    return gx


def openloop_transpose(xp):
    """``K^T`` in the array module ``xp``: the derived transpose for JAX, the fused one for NumPy."""
    return openloop_rmatvec if xp is np else openloop_rmatvec_derived


# ----------------------------------------------------------------------------- host helpers
def openloop_rhs(shape: OpenLoopShape, d: OpenLoopData, xp=np) -> tuple[OpenLoopY, OpenLoopY]:
    """Row right-hand sides ``g`` and row mask (1 = real row), as :class:`OpenLoopY`."""
    return OpenLoopY(d.gS, d.gT, d.gU), OpenLoopY(d.mS, d.mT, d.mU)


def openloop_bounds(shape: OpenLoopShape, d: OpenLoopData, xp=np) -> tuple[OpenLoopX, OpenLoopX]:
    """Box bounds of ``u`` as :class:`OpenLoopX` (``t`` bounds ``-inf, inf``; set by the caller)."""
    L, nv, m = shape.L, shape.n_v, shape.m
    B = d.lb.shape[-1]
    inf = xp.full((B,), np.inf)
    return (OpenLoopX(d.lb.reshape(L, nv, m, B), -inf), OpenLoopX(d.ub.reshape(L, nv, m, B), inf))


# ----------------------------------------------------------------------------- flat layout
def unpack_x(shape: OpenLoopShape, z, xp=np) -> OpenLoopX:
    """Flat ``(n_x + 1, B)`` (``build_openloop_lp`` layout, ``t`` last) -> :class:`OpenLoopX`."""
    B = z.shape[-1]
    return OpenLoopX(z[:-1].reshape(shape.L, shape.n_v, shape.m, B), z[-1])


def pack_x(x: OpenLoopX, xp=np):
    """:class:`OpenLoopX` -> flat ``(n_x + 1, B)``."""
    B = x.t.shape[-1]
    return xp.concatenate([x.u.reshape(-1, B), x.t[None]], axis=0)


def unpack_y(shape: OpenLoopShape, y, xp=np) -> OpenLoopY:
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
