"""Matrix-free margin-form tube LP operator ``K`` and ``K^T``, over the row families.

One instance is Problem 2 (:mod:`~tubejax.lp.declarations.tube_lp`) with ``z = (x, t)``, ``x`` laid
out as :class:`~tubejax.lp.declarations.tube_variables.TubeIndex`, ``t`` last; rows in
``build_tube_lp``'s order: every ``VertexIn`` family generically (``a[f] . p_l + b[f] eps_l + t <= g[f]``
at its steps), ``dynamics`` (C4; ``l = 0``, where ``q_k(0) = v_k`` is data, apart), then an input
family's hard rows without ``t`` (:class:`~.margin_operator.InputBlock`). Every coefficient is read off
the dense rows (:mod:`~tubejax.lp.declarations.tube_operator_data`), so ``K`` has the dense LP's rows by
construction. In the *radius* form (docs/math/radius.md) ``t`` is ``rho`` of ``W = rho W_0``. The
batch axis is LAST; ``xp=np`` re-checks certificates on the host. The fused ``K^T``
(:func:`tube_rmatvec`) is tested against ``jax.linear_transpose`` of :func:`tube_matvec`. The engines
read it as :data:`TUBE_OPERATOR`; what it shares with the open loop's is in :mod:`.margin_operator`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .margin_operator import (InputBlock, MarginOperator, OperatorShape, input_rows_matvec, input_rows_rhs, sum_left,
                              unpack)
from .tube_variables import TubeIndex

__all__ = ["TubeData", "VertexBlock", "TubeX", "TubeY", "tube_dims", "tube_matvec", "tube_rmatvec", "tube_rhs",
           "unpack_x", "unpack_y", "TUBE_OPERATOR", "SHARED_FIELDS"]


class VertexBlock(NamedTuple):
    """One ``VertexIn`` family's rows, batch axis ``B`` last.

    Attributes
    ----------
    a : (f, n, B)       coefficient of ``p_l``
    b : (f, B)          coefficient of ``eps_l``
    g : (f, B) or None  right-hand side
    mask : (f, B)       1 on real facets, 0 on padding
    W : (f, n + 1, B)   ``[a, b]`` stacked (for ``K^T``)
    """

    a: np.ndarray
    b: np.ndarray
    g: np.ndarray | None
    mask: np.ndarray
    W: np.ndarray


class TubeData(NamedTuple):
    """Per-instance coefficients of the row-normalised margin LP, batch axis ``B`` LAST.

    The dynamics rows (C4) at step ``l`` read ``H_z[r](A q_k(l) + B u_k(l) - p_{l+1})
    - eps_{l+1} h_z[r] + t <= -sigma_W(H_z[r])``; ``dyn_*`` hold them for ``l >= 1`` (where
    ``q_k(l) = p_l + eps_l v_k``) and ``dyn0_*`` for ``l = 0`` (``q_k(0) = v_k`` is data).

    Attributes
    ----------
    vertex_rows : tuple of VertexBlock, the ``VertexIn`` families' rows, in declaration order
    dyn_p, dyn_u, dyn_p_next : (n_v, f_z, n | m | n, B)
        Coefficients of ``p_l``, ``u_k(l)``, ``p_{l+1}`` (``l >= 1``).
    dyn_eps, dyn_eps_next, dyn_rhs : (n_v, f_z, B)
        Coefficients of ``eps_l``, ``eps_{l+1}`` and the right-hand side (``l >= 1``).
    dyn0_u, dyn0_p_next : (n_v, f_z, m | n, B); dyn0_eps_next, dyn0_rhs : (n_v, f_z, B)
        The same at ``l = 0``.
    x_lower, x_upper : (n_x, B), bounds on ``x`` (``t`` excluded)
    last_step : (L, B), one-hot of the instance's own horizon (``'last'`` rows act on ``p_L``)
    before_horizon : (L-1, B); within_horizon : (L, B)
        1 where step ``l`` is below / at most the instance's horizon.
    dyn0_stacked : (n_v, f_z, n+1+m, B); dyn_stacked : (n_v, f_z, 2n+2+m, B)
        ``[dyn0_p_next, dyn0_eps_next, dyn0_u]`` and ``[dyn_p, dyn_eps, dyn_p_next, dyn_eps_next, dyn_u]``
        stacked (for ``K^T``).
    dyn0_rho, dyn_rho : (n_v, f_z, B) or None, radius form: ``rho``'s coefficient at ``l = 0``, ``l >= 1``
    input_rows : InputBlock or None, the hard input rows (``shape.f_u > 0``)
    """

    vertex_rows: tuple
    dyn_p: np.ndarray
    dyn_eps: np.ndarray
    dyn_u: np.ndarray
    dyn_p_next: np.ndarray
    dyn_eps_next: np.ndarray
    dyn_rhs: np.ndarray
    dyn0_u: np.ndarray
    dyn0_p_next: np.ndarray
    dyn0_eps_next: np.ndarray
    dyn0_rhs: np.ndarray
    x_lower: np.ndarray
    x_upper: np.ndarray
    last_step: np.ndarray
    before_horizon: np.ndarray
    within_horizon: np.ndarray
    dyn0_stacked: np.ndarray
    dyn_stacked: np.ndarray
    dyn0_rho: np.ndarray | None = None
    dyn_rho: np.ndarray | None = None
    input_rows: InputBlock | None = None

    def lean(self) -> "TubeData":
        """The data ``K`` reads: right-hand sides and bounds dropped (they live in the
        PDHG problem's ``g``, ``lo``, ``hi``)."""
        return self._replace(vertex_rows=tuple(v._replace(g=None) for v in self.vertex_rows), dyn0_rhs=None,
                             dyn_rhs=None, x_lower=None, x_upper=None,
                             input_rows=None if self.input_rows is None else self.input_rows._replace(g=None))

    def map_coefficients(self, fn) -> "TubeData":
        """The same data with ``fn`` applied to every coefficient of ``K`` (``np.abs``: ``|K|``, for
        Pock-Chambolle scaling; ``np.square``: ``K o K``, row / column 2-norms for Ruiz scaling)."""
        vertex_rows = tuple(v._replace(a=fn(v.a), b=fn(v.b), W=fn(v.W)) for v in self.vertex_rows)
        input_rows = None if self.input_rows is None else self.input_rows._replace(H=fn(self.input_rows.H))
        return self._replace(vertex_rows=vertex_rows, input_rows=input_rows,
                             **{k: fn(getattr(self, k)) for k in _COEF if getattr(self, k) is not None})


#: Fields that depend only on ``Z`` and the system (shared by every instance with one ``Z``).
SHARED_FIELDS = ("dyn_p", "dyn_eps", "dyn_u", "dyn_p_next", "dyn_eps_next", "dyn_rhs", "dyn0_u", "dyn0_p_next",
                 "dyn0_eps_next")

_COEF = ("dyn_p", "dyn_eps", "dyn_u", "dyn_p_next", "dyn_eps_next", "dyn0_u", "dyn0_p_next", "dyn0_eps_next",
         "dyn0_stacked", "dyn_stacked", "dyn0_rho", "dyn_rho")


def _rows_of(kind: str, L: int) -> tuple:
    """Leading row axes of a ``VertexIn`` family with steps ``kind`` at padded horizon ``L``."""
    return {"interior": (L - 1,), "last": (), "all": (L,)}[kind]


def tube_dims(shape: OperatorShape) -> tuple[int, int]:
    """``(n_x, n_rows)`` of one instance, ``n_x`` without ``t``."""
    L = shape.L
    nv = sum(int(np.prod(_rows_of(k, L))) * f for k, f in zip(shape.v_steps, shape.f_v))
    return TubeIndex(L, shape.n, shape.n_v, shape.m).size, nv + L * shape.n_v * (shape.f_z + shape.f_u)


class TubeX(NamedTuple):
    """Primal vector of a batch: ``p (L, n, B)``, ``eps (L, B)``, ``u0 (n_v, m, B)`` (``l = 0``),
    ``u (L-1, n_v, m, B)`` (``l >= 1``), ``t (B,)``."""

    p: np.ndarray
    eps: np.ndarray
    u0: np.ndarray
    u: np.ndarray
    t: np.ndarray


class TubeY(NamedTuple):
    """Dual / row vector of a batch: ``vertex_rows`` (one array per ``VertexIn`` family: ``(L-1, f, B)``,
    ``(f, B)`` or ``(L, f, B)`` by its steps), ``y0 (n_v, f_z, B)`` (dynamics, ``l = 0``),
    ``y4 (L-1, n_v, f_z, B)`` (dynamics, ``l >= 1``), ``yu (L, n_v, f_u, B)`` (hard input rows;
    ``None`` without them)."""

    vertex_rows: tuple
    y0: np.ndarray
    y4: np.ndarray
    yu: np.ndarray | None = None


def _step_mask(d: TubeData, kind: str):
    """The instance-horizon mask of a ``VertexIn`` family's leading row axis (``None``: none)."""
    return {"interior": d.before_horizon[:, None], "last": None, "all": d.within_horizon[:, None]}[kind]


def tube_matvec(shape: OperatorShape, d: TubeData, x: TubeX, xp=np) -> TubeY:
    """``K x`` for a batch (``t`` included; pass ``t = 0`` for Problem 2 itself).

    In the radius form ``t`` is ``rho``: it enters the dynamics rows only, with ``dyn0_rho``, ``dyn_rho``.

    Returns
    -------
    TubeY -- the families' rows; padded rows give 0
    """
    L, n, m = shape.L, shape.n, shape.m
    p, eps, t = x.p, x.eps, x.t
    margin = shape.form != "radius"
    out = []
    for blk, kind in zip(d.vertex_rows, shape.v_steps):
        if kind == "last":                                          # p, eps at the instance's own horizon
            P, E = xp.sum(d.last_step[:, None] * p, axis=0), xp.sum(d.last_step * eps, axis=0)
            r = blk.b * E
            for i in range(n):
                r = r + blk.a[:, i] * P[None, i]
        else:
            P, E = (p[:L - 1], eps[:L - 1]) if kind == "interior" else (p, eps)
            r = blk.b[None] * E[:, None]
            for i in range(n):
                r = r + blk.a[None, :, i] * P[:, None, i]
        if margin:
            r = r + t
        mask = _step_mask(d, kind)
        out.append(r * blk.mask if mask is None else r * blk.mask[None] * mask)
    t0, t4 = (t, t) if margin else (d.dyn0_rho * t, d.dyn_rho[None] * t)       # t's (rho's) column
    r0 = d.dyn0_eps_next * eps[0] + t0
    r4 = d.dyn_eps[None] * eps[:L - 1, None, None] + d.dyn_eps_next[None] * eps[1:, None, None] + t4
    for i in range(n):
        r0 = r0 + d.dyn0_p_next[:, :, i] * p[0, None, None, i]
        r4 = (r4 + d.dyn_p[None, :, :, i] * p[:L - 1, None, None, i]
              + d.dyn_p_next[None, :, :, i] * p[1:, None, None, i])
    for j in range(m):
        r0 = r0 + d.dyn0_u[:, :, j] * x.u0[:, None, j]
        r4 = r4 + d.dyn_u[None, :, :, j] * x.u[:, :, None, j]
    ru = None
    if shape.f_u:                                                   # hard rows: no t, steps up to the horizon
        u = xp.concatenate([x.u0[None], x.u], axis=0)               # (L, n_v, m, B)
        ru = input_rows_matvec(d.input_rows, u) * d.within_horizon[:, None, None]
    return TubeY(tuple(out), r0, r4 * d.before_horizon[:, None, None], ru)


def tube_rmatvec(shape: OperatorShape, d: TubeData, y: TubeY, xp=np) -> TubeX:
    """``K^T y`` for a batch (padded rows are masked out), fused: the sums over the few facets and
    vertices are written out as multiply-adds of the stacked coefficients, so XLA fuses each block into
    one elementwise loop (docs/explanation/performance.md)."""
    L, n = shape.L, shape.n
    k = n + 1
    y0, y4 = y.y0, y.y4 * d.before_horizon[:, None, None]
    if xp is np:                          # on the host: the same sums in the same order, by einsum
        c0 = np.einsum("vfb,vfkb->vkb", y0, d.dyn0_stacked)
        c4 = np.einsum("lvfb,vfkb->lvkb", y4, d.dyn_stacked)
    else:
        c0 = sum_left([y0[:, f, None] * d.dyn0_stacked[:, f] for f in range(shape.f_z)])         # (nv, n+1+m, B)
        c4 = sum_left([y4[:, :, f, None] * d.dyn_stacked[None, :, f] for f in range(shape.f_z)])  # (L-1, nv, 2n+2+m, B)
    c0p = sum_left([c0[i, :k] for i in range(shape.n_v)])                              # (n+1, B): p_1, eps_1
    c4p = sum_left([c4[:, i, :2 * k] for i in range(shape.n_v)])                       # (L-1, 2n+2, B)
    z = xp.zeros((1,) + c0p.shape, c0p.dtype)
    first = (np.arange(L) == 0).astype(c0p.dtype)[:, None, None]
    prev = c4p[:, :k]                                                      # rows at l act on p_l, eps_l
    G = xp.concatenate([z, c4p[:, k:]], axis=0) + first * c0p[None]       # C4 at l acts on p_{l+1}
    gt = [xp.sum(y0, axis=(0, 1)), xp.sum(y4, axis=(0, 1, 2))]
    for blk, kind, yv, f_v in zip(d.vertex_rows, shape.v_steps, y.vertex_rows, shape.f_v):
        mask = _step_mask(d, kind)
        yv = yv * blk.mask if mask is None else yv * blk.mask[None] * mask
        gt.append(xp.sum(yv, axis=tuple(range(yv.ndim - 1))))
        if kind == "last":
            c = (np.einsum("fb,fkb->kb", yv, blk.W) if xp is np
                 else sum_left([yv[f, None] * blk.W[f] for f in range(f_v)]))
            G = G + d.last_step[:, None] * c[None]
        else:
            c = (np.einsum("sfb,fkb->skb", yv, blk.W) if xp is np
                 else sum_left([yv[:, f, None] * blk.W[None, f] for f in range(f_v)]))   # (S, n+1, B)
            if kind == "interior":
                prev = prev + c
            else:
                G = G + c
    G = G + xp.concatenate([prev, z], axis=0)
    cu0, cu = c0[:, k:], c4[:, :, 2 * k:]
    if shape.f_u:                                                   # hard input rows act on u only
        yu = y.yu * d.within_horizon[:, None, None]
        cu_all = sum_left([yu[:, :, f, None] * d.input_rows.H[None, None, f] for f in range(shape.f_u)])  # (L,n_v,m,B)
        cu0, cu = cu0 + cu_all[0], cu + cu_all[1:]
    if shape.form == "radius":                                              # rho: dynamics rows only
        gt = xp.sum(d.dyn0_rho * y0, axis=(0, 1)) + xp.sum(d.dyn_rho[None] * y4, axis=(0, 1, 2))
    else:
        gt = sum_left(gt)
    return TubeX(G[:, :n], G[:, n], cu0, cu, gt)


def tube_rhs(shape: OperatorShape, d: TubeData, xp=np) -> tuple[TubeY, TubeY]:
    """Row right-hand sides ``g`` and row mask (1 = real row), as :class:`TubeY`."""
    L, nv, fz = shape.L, shape.n_v, shape.f_z
    B = d.last_step.shape[-1]
    gs, ms = [], []
    for blk, kind in zip(d.vertex_rows, shape.v_steps):
        lead = _rows_of(kind, L)
        gs.append(xp.broadcast_to(blk.g, lead + blk.g.shape) + 0.0)
        mask = _step_mask(d, kind)
        ms.append(blk.mask + 0.0 if mask is None else blk.mask[None] * mask)
    gu, mu = input_rows_rhs(d.input_rows, d.within_horizon, nv, xp) if shape.f_u else (None, None)
    g = TubeY(tuple(gs), d.dyn0_rhs, xp.broadcast_to(d.dyn_rhs, (L - 1, nv, fz, B)) + 0.0, gu)
    mask = TubeY(tuple(ms), xp.ones((nv, fz, B)),
                 xp.broadcast_to(d.before_horizon[:, None, None], (L - 1, nv, fz, B)) + 0.0, mu)
    return g, mask


def unpack_x(shape: OperatorShape, z, xp=np) -> TubeX:
    """Flat ``(n_x + 1, B)`` (``build_tube_lp`` layout, ``t`` last) -> :class:`TubeX`."""
    L, n, m, nv = shape.L, shape.n, shape.m, shape.n_v
    return TubeX(*unpack(z, [(L, n), (L,), (nv, m), (L - 1, nv, m), ()]))


def unpack_y(shape: OperatorShape, y, xp=np) -> TubeY:
    """Flat ``(n_rows, B)`` (``build_tube_lp`` row order: the ``VertexIn`` families, then the
    dynamics rows, then the hard input rows) -> :class:`TubeY`."""
    L, nv, fz = shape.L, shape.n_v, shape.f_z
    *vertex_rows, y0, y4, yu = unpack(y, [_rows_of(k, L) + (f,) for k, f in zip(shape.v_steps, shape.f_v)]
                                      + [(nv, fz), (L - 1, nv, fz), (L, nv, shape.f_u) if shape.f_u else None])
    return TubeY(tuple(vertex_rows), y0, y4, yu)


#: The tube LP's matrix-free operator (its data is its own scaling coefficients).
TUBE_OPERATOR = MarginOperator(tube_matvec, tube_rmatvec, tube_rhs, unpack_x, unpack_y)
