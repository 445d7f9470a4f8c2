"""Matrix-free margin-form operator ``K``, ``K^T`` of the open-loop LP (docs/math/open-loop.md).

One instance is :func:`tubejax.lp.formulations.openloop.dense.build_openloop_lp` in margin form with
``z = (u, t)``, ``u`` of shape ``(L, n_v, m)`` laid out as
:class:`~tubejax.lp.formulations.openloop.dense.OpenLoopIndex` and ``t`` appended last. The rows come in
the order of ``build_openloop_lp``:

* C2: ``(L-1, n_v, f_s)`` -- ``H_S[f] . w_k(l) / N_S(l, f) + t <= g``, ``l = 1..L-1``;
* C3: ``(n_v, f_t)``      -- the same with the target facets at ``l = L``,

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

``K`` and ``K^T`` are written out explicitly (one ``einsum`` with the shared
``A^s B`` blocks, broadcast multiply-adds over the tiny facet / state axes);
:func:`openloop_coef_ops` gives the same operator through explicit per-instance
coefficients ``|K|``-ready, used on the host for the diagonal scaling only.

**Two forms** share the operator (:attr:`OpenLoopShape.form`, static): the *margin* form
above (``t``'s column is 1 on every row) and the *radius* form (docs/math/radius.md,
:mod:`tubejax.lp.formulations.radius`) for ``W = rho W_0``: ``t`` is ``rho``, the right-hand
sides omit ``sigma_{D_l}`` and ``t``'s column is ``sigma_{D_l}`` of the normalised row for
``W_0`` (``cS``, ``cT``; ``None`` in the margin form, whose traced code is unchanged). A zero
row is then ``c rho <= g``: kept when ``g < 0`` or ``c > 0``.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np

from ....model.geometry import support
from ..tube.dense import TubeProblem

__all__ = ["OpenLoopShape", "OpenLoopData", "OpenLoopX", "OpenLoopY", "openloop_shape",
           "build_openloop_data", "openloop_dims", "openloop_matvec", "openloop_rmatvec",
           "openloop_rhs", "openloop_bounds", "openloop_coef_data", "openloop_coef_ops",
           "pack_x", "unpack_x", "pack_y", "unpack_y", "ab_blocks"]

_ZERO_ROW = 1e-12          # as in tubejax.lp.formulations.openloop.dense


class OpenLoopShape(NamedTuple):
    """Static shape of a group (hashable; keys the compiled executables).

    ``ab`` is ``A^s B`` for ``s = 0 .. L-1`` flattened to a tuple of floats (shape
    ``(L, n, m)``): the operator's shared data, a compile-time constant.
    """

    L: int
    n: int
    m: int
    n_v: int
    f_s: int
    f_t: int
    ab: tuple
    form: str = "margin"


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


class OpenLoopX(NamedTuple):
    """Primal vector of a batch: ``u (L, n_v, m, B)``, ``t (B,)``."""

    u: np.ndarray
    t: np.ndarray


class OpenLoopY(NamedTuple):
    """Row vector of a batch: ``yS (L-1, n_v, f_s, B)`` (C2), ``yT (n_v, f_t, B)`` (C3)."""

    yS: np.ndarray
    yT: np.ndarray



def _pad_rows(Hs: Sequence[np.ndarray], hs: Sequence[np.ndarray], f: int):
    """Facet rows ``(B, f, n)``, offsets ``(B, f)`` and a mask ``(B, f)``, padded with zero rows."""
    B, n = len(Hs), Hs[0].shape[1]
    H = np.zeros((B, f, n))
    h = np.zeros((B, f))
    mask = np.zeros((B, f))
    for b, (Hb, hb) in enumerate(zip(Hs, hs)):
        H[b, :Hb.shape[0]] = Hb
        h[b, :hb.shape[0]] = hb
        mask[b, :hb.shape[0]] = 1.0
    return H, h, mask


def _powers(A: np.ndarray, L: int) -> list[np.ndarray]:
    out = [np.eye(A.shape[0])]
    for _ in range(L):
        out.append(A @ out[-1])
    return out


def ab_blocks(shape: OpenLoopShape) -> np.ndarray:
    """``A^s B`` of the group, shape ``(L, n, m)``."""
    return np.asarray(shape.ab, float).reshape(shape.L, shape.n, shape.m)


def _transfer(shape: OpenLoopShape) -> np.ndarray:
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
    return shape.L * shape.n_v * shape.m, (shape.L - 1) * shape.n_v * shape.f_s + shape.n_v * shape.f_t


def openloop_shape(prob: TubeProblem, L: int | None = None, f_s: int | None = None,
                   f_t: int | None = None) -> OpenLoopShape:
    """The :class:`OpenLoopShape` of a problem (optionally padded)."""
    s = prob.system
    L = int(prob.L) if L is None else int(L)
    Ap = _powers(s.A, L)
    ab = np.stack([Ap[k] @ s.B for k in range(L)])
    return OpenLoopShape(L, s.n, s.m, prob.source.n_vertices,
                         prob.safe.H.shape[0] if f_s is None else int(f_s),
                         prob.target.H.shape[0] if f_t is None else int(f_t),
                         tuple(float(v) for v in ab.ravel()))


def build_openloop_data(problems: Sequence[TubeProblem], L_pad: int | None = None,
                        f_s: int | None = None, f_t: int | None = None,
                        W0=None) -> tuple[OpenLoopShape, OpenLoopData]:
    """Stack the geometry of problems sharing one system and ``n_v`` (horizons may differ).

    Parameters
    ----------
    problems : sequence of TubeProblem, length B (``Z`` is ignored)
    L_pad : int, optional
        Padded horizon (default: the largest ``L``). Rows beyond an instance's own
        horizon are masked; its inputs beyond ``L`` are only boxed, so margins and
        certificates are unchanged.
    f_s, f_t : int, optional
        Padded facet counts (default: the largest in the group).
    W0 : Ball or Polytope, optional
        The radius form for ``W = rho W0`` (see the module docstring): the problems' own
        ``W`` is ignored, ``cS`` / ``cT`` are filled and ``shape.form`` is ``'radius'``.

    Returns
    -------
    shape : OpenLoopShape
    data : OpenLoopData of NumPy float64 arrays, batch axis last
    """
    p0 = problems[0]
    sysm = p0.system
    A = sysm.A
    n, m = sysm.n, sysm.m
    nv = p0.source.n_vertices
    for p in problems:
        if p.system is not sysm or p.source.n_vertices != nv:
            raise ValueError("build_openloop_data needs one system and equal n_v in a group")
    Ls = np.array([int(p.L) for p in problems])
    L = int(Ls.max()) if L_pad is None else int(L_pad)
    if Ls.max() > L:
        raise ValueError(f"L_pad = {L} is below a problem's horizon {Ls.max()}")
    f_s = max(p.safe.H.shape[0] for p in problems) if f_s is None else int(f_s)
    f_t = max(p.target.H.shape[0] for p in problems) if f_t is None else int(f_t)
    radius = W0 is not None
    shape = openloop_shape(p0, L, f_s, f_t)._replace(form="radius" if radius else "margin")
    ab = ab_blocks(shape)                                        # (L, n, m)
    Ap = _powers(A, L)
    Bsz = len(problems)
    V = np.stack([p.source.vertices for p in problems])          # (B, nv, n)
    HS, hS, fmS = _pad_rows([p.safe.H for p in problems], [p.safe.h for p in problems], f_s)
    HT, hT, fmT = _pad_rows([p.target.H for p in problems], [p.target.h for p in problems], f_t)

    def rows(H, h, fm, ells):
        """Normalised rows, rhs and masks at steps ``ells`` (each >= 1) for facets ``(B, f, n)``."""
        sq = np.stack([np.sum((H @ ab[s]) ** 2, axis=-1) for s in range(L)], axis=0)   # (L, B, f)
        cum = np.cumsum(sq, axis=0)                                 # cum[l-1] = sum_{s<l}
        sig = np.zeros((L + 1,) + H.shape[:2])                      # sigma_{D_l}(H), (L+1, B, f)
        for t in range(L):
            sig[t + 1] = sig[t] + support(W0 if radius else sysm.W, H @ Ap[t])
        a, g, mk, c = [], [], [], []
        for ell in ells:                                            # ell: (B,) ints
            bi = np.arange(Bsz)
            zero = np.sqrt(cum[ell - 1, bi]) <= _ZERO_ROW            # (B, f): no input dependence
            free = np.einsum("bkn,bfn->bkf", np.einsum("bkn,bpn->bkp", V, Ap_stack[ell]), H)
            raw = h[:, None, :] - (0.0 if radius else sig[ell, bi][:, None, :]) - free   # (B, nv, f)
            scale = np.where(fm > 0, np.linalg.norm(H, axis=-1), 1.0)   # the facet normal's length
            a.append(np.where(zero[..., None], 0.0, H / scale[..., None]))
            g.append(raw / scale[:, None, :])
            c.append(sig[ell, bi] / scale if radius else np.zeros_like(scale))     # (B, f)
            idle = zero[:, None, :] & (raw >= 0) & (c[-1][:, None, :] <= 0)        # a redundant zero row
            mk.append(fm[:, None, :] * np.where(idle, 0.0, 1.0))
        return a, g, mk, c

    Ap_stack = np.stack(Ap)                                         # (L+1, n, n)
    # C2 at l = 1..L-1 (masked beyond the own horizon)
    if L > 1:
        aS, gS, mS, cS = rows(HS, hS, fmS, [np.full(Bsz, ell) for ell in range(1, L)])
        aS, gS, mS, cS = np.stack(aS), np.stack(gS), np.stack(mS), np.stack(cS)   # (L-1, B, ...)
        live = (np.arange(1, L)[:, None] < Ls[None, :]).astype(float)          # (L-1, B)
        mS = mS * live[:, :, None, None]
        gS = np.where(mS > 0, gS, 0.0)
    else:
        aS, gS, mS = np.zeros((0, Bsz, f_s, n)), np.zeros((0, Bsz, nv, f_s)), np.zeros((0, Bsz, nv, f_s))
        cS = np.zeros((0, Bsz, f_s))
    (aT,), (gT,), (mT,), (cT,) = rows(HT, hT, fmT, [Ls])
    gT = np.where(mT > 0, gT, 0.0)
    sel = (np.arange(L)[None, :] == Ls[:, None] - 1).astype(float)             # (B, L)
    ulo, uhi = sysm.u_box()
    lb = np.broadcast_to(np.tile(ulo, L * nv)[:, None], (L * nv * m, Bsz))
    ub = np.broadcast_to(np.tile(uhi, L * nv)[:, None], (L * nv * m, Bsz))
    last = lambda a: np.ascontiguousarray(np.moveaxis(a, 1, -1))            # noqa: E731  (l, B, ...) -> (l, ..., B)
    data = OpenLoopData(
        aS=last(aS), aT=np.ascontiguousarray(np.moveaxis(aT, 0, -1)), sel=np.ascontiguousarray(sel.T),
        gS=last(gS), gT=np.ascontiguousarray(np.moveaxis(gT, 0, -1)),
        mS=last(mS), mT=np.ascontiguousarray(np.moveaxis(mT, 0, -1)),
        lb=np.ascontiguousarray(lb), ub=np.ascontiguousarray(ub))
    if radius:
        data = data._replace(cS=last(cS), cT=np.ascontiguousarray(cT.T))
    return shape, data


# ----------------------------------------------------------------------------- the operator
def openloop_matvec(shape: OpenLoopShape, d: OpenLoopData, x: OpenLoopX, xp=np) -> OpenLoopY:
    """``K x`` for a batch (``t`` included; pass ``t = 0`` for the decision problem).

    No row mask is applied (masked rows are ignored by the solver and the certificates).
    """
    L, n = shape.L, shape.n
    M = _transfer(shape)                                              # (L, L, n, m), shared
    w = xp.einsum("ltnj,tkjb->lknb", M, x.u)                          # w[l] = w_k(l+1)
    if shape.form == "radius":
        rS = xp.zeros(d.aS.shape[:1] + (shape.n_v, shape.f_s) + x.t.shape) + d.cS[:, None] * x.t
        rT = xp.zeros((shape.n_v, shape.f_t) + x.t.shape) + d.cT[None] * x.t
    else:
        rS = xp.zeros(d.aS.shape[:1] + (shape.n_v, shape.f_s) + x.t.shape) + x.t
        rT = xp.zeros((shape.n_v, shape.f_t) + x.t.shape) + x.t
    wL = xp.sum(d.sel[:, None, None] * w, axis=0)                     # (nv, n, B): w at the own horizon
    for i in range(n):
        rS = rS + d.aS[:, None, :, i] * w[:L - 1, :, None, i]
        rT = rT + d.aT[None, :, i] * wL[:, None, i]
    return OpenLoopY(rS, rT)


def openloop_rmatvec(shape: OpenLoopShape, d: OpenLoopData, y: OpenLoopY, xp=np) -> OpenLoopX:
    """``K^T y`` for a batch."""
    n = shape.n
    M = _transfer(shape)
    cS = xp.stack([xp.sum(d.aS[:, None, :, i] * y.yS, axis=2) for i in range(n)], axis=2)  # (L-1, nv, n, B)
    cT = xp.stack([xp.sum(d.aT[None, :, i] * y.yT, axis=1) for i in range(n)], axis=1)     # (nv, n, B)
    z = xp.zeros((1,) + cT.shape)
    gw = xp.concatenate([cS, z], axis=0) + d.sel[:, None, None] * cT[None]                 # (L, nv, n, B)
    gu = xp.einsum("ltnj,lknb->tkjb", M, gw)
    if shape.form == "radius":
        gt = xp.sum(d.cS[:, None] * y.yS, axis=(0, 1, 2)) + xp.sum(d.cT[None] * y.yT, axis=(0, 1))
    else:
        gt = xp.sum(y.yS, axis=(0, 1, 2)) + xp.sum(y.yT, axis=(0, 1))
    return OpenLoopX(gu, gt)


# ----------------------------------------------------------------------------- host helpers
def openloop_rhs(shape: OpenLoopShape, d: OpenLoopData, xp=np) -> tuple[OpenLoopY, OpenLoopY]:
    """Row right-hand sides ``g`` and row mask (1 = real row), as :class:`OpenLoopY`."""
    return OpenLoopY(d.gS, d.gT), OpenLoopY(d.mS, d.mT)


def openloop_bounds(shape: OpenLoopShape, d: OpenLoopData, xp=np) -> tuple[OpenLoopX, OpenLoopX]:
    """Box bounds of ``u`` as :class:`OpenLoopX` (``t`` bounds ``-inf, inf``; set by the caller)."""
    L, nv, m = shape.L, shape.n_v, shape.m
    B = d.lb.shape[-1]
    inf = xp.full((B,), np.inf)
    return (OpenLoopX(d.lb.reshape(L, nv, m, B), -inf), OpenLoopX(d.ub.reshape(L, nv, m, B), inf))


class OpenLoopCoef(NamedTuple):
    """Explicit per-instance coefficients (host only; for the diagonal scaling).

    CS : (L-1, f_s, L, m, B)  coefficient of ``u_k(t)[j]`` in C2 row ``(l, k, f)``
    CT : (f_t, L, m, B)       the same for C3
    mS, mT : row masks (dropped rows get no coefficient, not even ``t``'s)
    tS : (L-1, f_s, B) or (1, 1, 1)   ``t``'s coefficient in C2 rows (1 in the margin form)
    tT : (f_t, B) or (1, 1)           ``t``'s coefficient in C3 rows
    """

    CS: np.ndarray
    CT: np.ndarray
    mS: np.ndarray
    mT: np.ndarray
    tS: np.ndarray
    tT: np.ndarray


def openloop_coef_data(shape: OpenLoopShape, d: OpenLoopData) -> OpenLoopCoef:
    """The same operator as explicit coefficients (``|K|`` = :func:`numpy.abs` of them)."""
    M = _transfer(shape)                                              # (L, L, n, m)
    CS = np.einsum("lfnb,ltnj->lftjb", d.aS, M[:shape.L - 1])
    CT = np.einsum("lb,fnb,ltnj->ftjb", d.sel, d.aT, M)
    if shape.form == "radius":
        return OpenLoopCoef(CS, CT, d.mS, d.mT, d.cS, d.cT)
    return OpenLoopCoef(CS, CT, d.mS, d.mT, np.ones((1, 1, 1)), np.ones((1, 1)))


def openloop_coef_ops(shape: OpenLoopShape):
    """``matvec``, ``rmatvec`` on flat vectors with :class:`OpenLoopCoef` data (NumPy, host).

    With ``coef._replace(CS=abs(CS), CT=abs(CT), tS=abs(tS), tT=abs(tT))`` they apply ``|K|``,
    with squares ``K o K`` (the ``t`` column is ``tS``, ``tT`` on real rows, 0 on masked ones).
    """
    def mv(c: OpenLoopCoef, z):
        x = unpack_x(shape, z)
        rS = (np.einsum("lftjb,tkjb->lkfb", c.CS, x.u) + c.tS[:, None] * x.t) * c.mS
        rT = (np.einsum("ftjb,tkjb->kfb", c.CT, x.u) + c.tT[None] * x.t) * c.mT
        return pack_y(OpenLoopY(rS, rT))

    def rmv(c: OpenLoopCoef, yv):
        y = unpack_y(shape, yv)
        yS, yT = y.yS * c.mS, y.yT * c.mT
        gu = np.einsum("lftjb,lkfb->tkjb", c.CS, yS) + np.einsum("ftjb,kfb->tkjb", c.CT, yT)
        gt = np.sum(c.tS[:, None] * yS, axis=(0, 1, 2)) + np.sum(c.tT[None] * yT, axis=(0, 1))
        return pack_x(OpenLoopX(gu, gt))

    return mv, rmv


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
    return OpenLoopY(y[:o].reshape(L - 1, nv, fs, B), y[o:o + nv * ft].reshape(nv, ft, B))


def pack_y(y: OpenLoopY, xp=np):
    """:class:`OpenLoopY` -> flat ``(n_rows, B)``."""
    B = y.yT.shape[-1]
    return xp.concatenate([y.yS.reshape(-1, B), y.yT.reshape(-1, B)], axis=0)
