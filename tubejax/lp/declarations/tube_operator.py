"""Matrix-free margin-form tube LP operator ``K`` and ``K^T``, over the row families.

One instance is Problem 2 of :mod:`tubejax.lp.declarations.tube_lp` in margin form with
``z = (x, t)``, ``x`` laid out exactly as :class:`~tubejax.lp.declarations.tube_lp.TubeIndex`
(``p (L, n)``, ``eps (L,)``, ``u (L, n_v, m)``) and ``t`` appended last. The rows are those of
the margin families of :data:`~tubejax.lp.declarations.tube_families.TUBE_FAMILIES`, in the
order of :func:`~tubejax.lp.declarations.tube_lp.build_tube_lp`'s row layout:

* every :class:`~tubejax.lp.declarations.tube_families.VertexIn` family (``safe``, ``target``,
  ...), generically: ``a[f] . p_l + b[f] eps_l + t <= g[f]`` at the family's steps
  (``'interior'``: ``(L-1, f)`` rows, ``'last'``: ``(f,)`` rows at the instance's own ``L``,
  ``'all'``: ``(L, f)``);
* ``dynamics`` (C4): ``(L, n_v, f_z)`` -- ``H_z[r](A q_k(l) + B u_k(l) - p_{l+1}) - eps_{l+1}
  h_z[r] + t <= -sigma_W(H_z[r])``, split into ``l = 0`` (``q_k(0) = v_k`` is data) and ``l >= 1``;
* the hard rows of an input family (C5 of a non-box ``U``, :class:`InputBlock`): ``(L, n_v, f_u)`` --
  ``H_u[r] u_k(l) <= h_u[r]``, without ``t`` (appended after the margin rows, as ``build_tube_lp``'s
  ``G_hard`` follows its ``G``).

Every coefficient is read off the dense rows that the families derive
(:mod:`tubejax.lp.declarations.tube_operator_data`), so ``K`` has the dense LP's rows by
construction; only how each family's rows act on the variables (which steps, which vertex)
is written here, once per family kind.

**Two forms** share the operator (:attr:`TubeShape.form`, static): the *margin* form above
(``t``'s column is 1 on every real row) and the *radius* form (docs/math/radius.md,
:mod:`tubejax.lp.batch.radius`): ``t`` is the radius ``rho`` of ``W = rho W_0``, its
column is ``R0``, ``R4`` on the dynamics rows and 0 elsewhere.

The batch axis is the LAST axis of every array (on CPU ~10x faster than ``vmap``'s leading
batch axis: reductions over tiny axes become adds of contiguous vectors). Primal and dual
vectors are pytrees (:class:`TubeX`, :class:`TubeY`); the functions accept NumPy arrays too
(``xp=np``) so certificates can be re-checked on the host; :func:`pack_x` / :func:`pack_y`
give the flat ``build_tube_lp`` layout. ``K^T`` is written fused (:func:`tube_rmatvec`); it is
tested against ``jax.linear_transpose`` of :func:`tube_matvec` and measured against it in
``experiments/benchmark.py``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .tube_lp import TubeIndex

__all__ = ["TubeShape", "TubeData", "VertexBlock", "InputBlock", "TubeX", "TubeY", "tube_dims", "tube_matvec",
           "tube_rmatvec", "tube_abs_data", "tube_square_data", "tube_rhs", "tube_bounds",
           "pack_x", "unpack_x", "pack_y", "unpack_y", "SHARED_FIELDS"]


class TubeShape(NamedTuple):
    """Static shape of a group: horizon, dimensions, the ``VertexIn`` families' (padded) facet
    counts and step kinds, in declaration order, the form, and the facet count ``f_u`` of the
    hard input rows (0: none, a box ``U`` is variable bounds)."""

    L: int
    n: int
    m: int
    n_v: int
    f_z: int
    f_v: tuple
    v_steps: tuple
    form: str = "margin"
    f_u: int = 0


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


class InputBlock(NamedTuple):
    """The hard rows of an input family, ``H u_k(l) <= g`` at every step and vertex, batch axis ``B`` last.

    Attributes
    ----------
    H : (f_u, m, B)         unit rows
    g : (f_u, B) or None    right-hand sides
    """

    H: np.ndarray
    g: np.ndarray | None


class TubeData(NamedTuple):
    """Per-instance coefficients of the row-normalised margin LP, batch axis ``B`` LAST.

    Attributes
    ----------
    vin : tuple of VertexBlock      the ``VertexIn`` families, in declaration order
    A4 : (n_v, f_z, n, B)   dynamics (``l >= 1``) coefficient of ``p_l``
    E4 : (n_v, f_z, B)      dynamics (``l >= 1``) coefficient of ``eps_l``
    U4 : (n_v, f_z, m, B)   dynamics (``l >= 1``) coefficient of ``u_k(l)``
    P4 : (n_v, f_z, n, B)   dynamics (``l >= 1``) coefficient of ``p_{l+1}``
    F4 : (n_v, f_z, B)      dynamics (``l >= 1``) coefficient of ``eps_{l+1}``
    g4 : (n_v, f_z, B)      dynamics (``l >= 1``) rhs
    U0, P0, F0, g0 :        the same for ``l = 0`` (``q_k(0) = v_k`` is constant)
    lb, ub : (n_x, B)       bounds on ``x`` (``t`` excluded)
    sel : (L, B)            one-hot of the instance's own horizon (``'last'`` rows act on ``p_L``)
    m2 : (L-1, B)           1 where step ``l`` is below the instance's horizon
    mL : (L, B)             1 where step ``l`` is at most the instance's horizon
    W0 : (n_v, f_z, n+1+m, B)      ``[P0, F0, U0]``
    W4 : (n_v, f_z, 2n+2+m, B)     ``[A4, E4, P4, F4, U4]``
    R0 : (n_v, f_z, B) or None      radius form: coefficient of ``rho`` in the dynamics rows at ``l = 0``
    R4 : (n_v, f_z, B) or None      radius form: the same at ``l >= 1``
    inp : InputBlock or None        the hard input rows (``shape.f_u > 0``)
    """

    vin: tuple
    A4: np.ndarray
    E4: np.ndarray
    U4: np.ndarray
    P4: np.ndarray
    F4: np.ndarray
    g4: np.ndarray
    U0: np.ndarray
    P0: np.ndarray
    F0: np.ndarray
    g0: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    sel: np.ndarray
    m2: np.ndarray
    mL: np.ndarray
    W0: np.ndarray
    W4: np.ndarray
    R0: np.ndarray | None = None
    R4: np.ndarray | None = None
    inp: InputBlock | None = None

    def lean(self) -> "TubeData":
        """The data ``K`` reads: right-hand sides and bounds dropped (they live in the
        PDHG problem's ``g``, ``lo``, ``hi``)."""
        return self._replace(vin=tuple(v._replace(g=None) for v in self.vin), g0=None, g4=None, lb=None, ub=None,
                             inp=None if self.inp is None else self.inp._replace(g=None))


#: Fields that depend only on ``Z`` and the system (shared by every instance with one ``Z``).
SHARED_FIELDS = ("A4", "E4", "U4", "P4", "F4", "g4", "U0", "P0", "F0")

_COEF = ("A4", "E4", "U4", "P4", "F4", "U0", "P0", "F0", "W0", "W4", "R0", "R4")


def _rows_of(kind: str, L: int) -> tuple:
    """Leading row axes of a ``VertexIn`` family with steps ``kind`` at padded horizon ``L``."""
    return {"interior": (L - 1,), "last": (), "all": (L,)}[kind]


def tube_dims(shape: TubeShape) -> tuple[int, int]:
    """``(n_x, n_rows)`` of one instance, ``n_x`` without ``t``."""
    L = shape.L
    nv = sum(int(np.prod(_rows_of(k, L))) * f for k, f in zip(shape.v_steps, shape.f_v))
    return TubeIndex(L, shape.n, shape.n_v, shape.m).size, nv + L * shape.n_v * (shape.f_z + shape.f_u)


def _map_coef(d: TubeData, fn) -> TubeData:
    vin = tuple(v._replace(a=fn(v.a), b=fn(v.b), W=fn(v.W)) for v in d.vin)
    inp = None if d.inp is None else d.inp._replace(H=fn(d.inp.H))
    return d._replace(vin=vin, inp=inp, **{k: fn(getattr(d, k)) for k in _COEF if getattr(d, k) is not None})


def tube_abs_data(d: TubeData, xp=np) -> TubeData:
    """``|K|``: the same data with absolute coefficients (for Pock-Chambolle scaling)."""
    return _map_coef(d, xp.abs)


def tube_square_data(d: TubeData, xp=np) -> TubeData:
    """``K o K``: squared coefficients (row / column 2-norms for Ruiz scaling)."""
    return _map_coef(d, lambda a: a ** 2)


class TubeX(NamedTuple):
    """Primal vector of a batch: ``p (L, n, B)``, ``eps (L, B)``, ``u0 (n_v, m, B)`` (``l = 0``),
    ``u (L-1, n_v, m, B)`` (``l >= 1``), ``t (B,)``."""

    p: np.ndarray
    eps: np.ndarray
    u0: np.ndarray
    u: np.ndarray
    t: np.ndarray


class TubeY(NamedTuple):
    """Dual / row vector of a batch: ``vin`` (one array per ``VertexIn`` family: ``(L-1, f, B)``,
    ``(f, B)`` or ``(L, f, B)`` by its steps), ``y0 (n_v, f_z, B)`` (dynamics, ``l = 0``),
    ``y4 (L-1, n_v, f_z, B)`` (dynamics, ``l >= 1``), ``yu (L, n_v, f_u, B)`` (hard input rows;
    ``None`` without them)."""

    vin: tuple
    y0: np.ndarray
    y4: np.ndarray
    yu: np.ndarray | None = None


def _step_mask(d: TubeData, kind: str):
    """The instance-horizon mask of a ``VertexIn`` family's leading row axis (``None``: none)."""
    return {"interior": d.m2[:, None], "last": None, "all": d.mL[:, None]}[kind]


def tube_matvec(shape: TubeShape, d: TubeData, x: TubeX, xp=np) -> TubeY:
    """``K x`` for a batch (``t`` included; pass ``t = 0`` for Problem 2 itself).

    In the radius form ``t`` is ``rho``: it enters the dynamics rows only, with ``R0``, ``R4``.

    Returns
    -------
    TubeY -- the families' rows; padded rows give 0
    """
    L, n, m = shape.L, shape.n, shape.m
    p, eps, t = x.p, x.eps, x.t
    margin = shape.form != "radius"
    out = []
    for blk, kind in zip(d.vin, shape.v_steps):
        if kind == "last":                                          # p, eps at the instance's own horizon
            P, E = xp.sum(d.sel[:, None] * p, axis=0), xp.sum(d.sel * eps, axis=0)
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
    if margin:
        r0 = d.F0 * eps[0] + t
        r4 = d.E4[None] * eps[:L - 1, None, None] + d.F4[None] * eps[1:, None, None] + t
    else:
        r0 = d.F0 * eps[0] + d.R0 * t
        r4 = d.E4[None] * eps[:L - 1, None, None] + d.F4[None] * eps[1:, None, None] + d.R4[None] * t
    for i in range(n):
        r0 = r0 + d.P0[:, :, i] * p[0, None, None, i]
        r4 = (r4 + d.A4[None, :, :, i] * p[:L - 1, None, None, i]
              + d.P4[None, :, :, i] * p[1:, None, None, i])
    for j in range(m):
        r0 = r0 + d.U0[:, :, j] * x.u0[:, None, j]
        r4 = r4 + d.U4[None, :, :, j] * x.u[:, :, None, j]
    ru = None
    if shape.f_u:                                                   # hard rows: no t, steps up to the horizon
        u = xp.concatenate([x.u0[None], x.u], axis=0)               # (L, n_v, m, B)
        ru = _sum([d.inp.H[None, None, :, j] * u[:, :, None, j] for j in range(m)]) * d.mL[:, None, None]
    return TubeY(tuple(out), r0, r4 * d.m2[:, None, None], ru)


def _sum(terms):
    """Left-to-right sum of a sequence of arrays."""
    acc = terms[0]
    for t in terms[1:]:
        acc = acc + t
    return acc


def tube_rmatvec(shape: TubeShape, d: TubeData, y: TubeY, xp=np) -> TubeX:
    """``K^T y`` for a batch (padded rows are masked out), fused.

    Uses the stacked coefficients ``VertexBlock.W``, ``W0``, ``W4``. The sums over the few
    facets and vertices are written out as multiply-adds: XLA then fuses each block into
    one elementwise loop (~2.3x faster than ``jax.linear_transpose`` of :func:`tube_matvec`
    on a 2-core CPU; ``experiments/benchmark.py`` measures it).
    """
    L, n = shape.L, shape.n
    k = n + 1
    y0, y4 = y.y0, y.y4 * d.m2[:, None, None]
    if xp is np:                          # on the host: the same sums in the same order, by einsum
        c0 = np.einsum("vfb,vfkb->vkb", y0, d.W0)
        c4 = np.einsum("lvfb,vfkb->lvkb", y4, d.W4)
    else:
        c0 = _sum([y0[:, f, None] * d.W0[:, f] for f in range(shape.f_z)])         # (nv, n+1+m, B)
        c4 = _sum([y4[:, :, f, None] * d.W4[None, :, f] for f in range(shape.f_z)])  # (L-1, nv, 2n+2+m, B)
    c0p = _sum([c0[i, :k] for i in range(shape.n_v)])                              # (n+1, B): p_1, eps_1
    c4p = _sum([c4[:, i, :2 * k] for i in range(shape.n_v)])                       # (L-1, 2n+2, B)
    z = xp.zeros((1,) + c0p.shape, c0p.dtype)
    first = (np.arange(L) == 0).astype(c0p.dtype)[:, None, None]
    prev = c4p[:, :k]                                                      # rows at l act on p_l, eps_l
    G = xp.concatenate([z, c4p[:, k:]], axis=0) + first * c0p[None]       # C4 at l acts on p_{l+1}
    gt = [xp.sum(y0, axis=(0, 1)), xp.sum(y4, axis=(0, 1, 2))]
    for blk, kind, yv, f_v in zip(d.vin, shape.v_steps, y.vin, shape.f_v):
        mask = _step_mask(d, kind)
        yv = yv * blk.mask if mask is None else yv * blk.mask[None] * mask
        gt.append(xp.sum(yv, axis=tuple(range(yv.ndim - 1))))
        if kind == "last":
            c = (np.einsum("fb,fkb->kb", yv, blk.W) if xp is np
                 else _sum([yv[f, None] * blk.W[f] for f in range(f_v)]))
            G = G + d.sel[:, None] * c[None]
        else:
            c = (np.einsum("sfb,fkb->skb", yv, blk.W) if xp is np
                 else _sum([yv[:, f, None] * blk.W[None, f] for f in range(f_v)]))   # (S, n+1, B)
            if kind == "interior":
                prev = prev + c
            else:
                G = G + c
    G = G + xp.concatenate([prev, z], axis=0)
    cu0, cu = c0[:, k:], c4[:, :, 2 * k:]
    if shape.f_u:                                                   # hard input rows act on u only
        yu = y.yu * d.mL[:, None, None]
        cu_all = _sum([yu[:, :, f, None] * d.inp.H[None, None, f] for f in range(shape.f_u)])   # (L, n_v, m, B)
        cu0, cu = cu0 + cu_all[0], cu + cu_all[1:]
    if shape.form == "radius":                                              # rho: dynamics rows only
        gt = xp.sum(d.R0 * y0, axis=(0, 1)) + xp.sum(d.R4[None] * y4, axis=(0, 1, 2))
    else:
        gt = _sum(gt)
    return TubeX(G[:, :n], G[:, n], cu0, cu, gt)


def tube_rhs(shape: TubeShape, d: TubeData, xp=np) -> tuple[TubeY, TubeY]:
    """Row right-hand sides ``g`` and row mask (1 = real row), as :class:`TubeY`."""
    L, nv, fz = shape.L, shape.n_v, shape.f_z
    B = d.sel.shape[-1]
    gs, ms = [], []
    for blk, kind in zip(d.vin, shape.v_steps):
        lead = _rows_of(kind, L)
        gs.append(xp.broadcast_to(blk.g, lead + blk.g.shape) + 0.0)
        mask = _step_mask(d, kind)
        ms.append(blk.mask + 0.0 if mask is None else blk.mask[None] * mask)
    gu = mu = None
    if shape.f_u:
        gu = xp.broadcast_to(d.inp.g, (L, nv) + d.inp.g.shape) + 0.0
        mu = xp.broadcast_to(d.mL[:, None, None], (L, nv, shape.f_u, B)) + 0.0
    g = TubeY(tuple(gs), d.g0, xp.broadcast_to(d.g4, (L - 1, nv, fz, B)) + 0.0, gu)
    mask = TubeY(tuple(ms), xp.ones((nv, fz, B)), xp.broadcast_to(d.m2[:, None, None], (L - 1, nv, fz, B)) + 0.0, mu)
    return g, mask


def unpack_x(shape: TubeShape, z, xp=np) -> TubeX:
    """Flat ``(n_x + 1, B)`` (``build_tube_lp`` layout, ``t`` last) -> :class:`TubeX`."""
    L, n, m, nv = shape.L, shape.n, shape.m, shape.n_v
    B = z.shape[-1]
    o = L * n + L
    u = z[o:o + L * nv * m].reshape(L, nv, m, B)
    return TubeX(z[:L * n].reshape(L, n, B), z[L * n:o], u[0], u[1:], z[-1])


def pack_x(x: TubeX, xp=np):
    """:class:`TubeX` -> flat ``(n_x + 1, B)``."""
    B = x.t.shape[-1]
    return xp.concatenate([x.p.reshape(-1, B), x.eps, x.u0.reshape(-1, B), x.u.reshape(-1, B),
                           x.t[None]], axis=0)


def unpack_y(shape: TubeShape, y, xp=np) -> TubeY:
    """Flat ``(n_rows, B)`` (``build_tube_lp`` row order: the ``VertexIn`` families, then the
    dynamics rows, then the hard input rows) -> :class:`TubeY`."""
    L, nv, fz = shape.L, shape.n_v, shape.f_z
    B = y.shape[-1]
    vin, o = [], 0
    for kind, f in zip(shape.v_steps, shape.f_v):
        lead = _rows_of(kind, L)
        size = int(np.prod(lead)) * f
        vin.append(y[o:o + size].reshape(lead + (f, B)))
        o += size
    o4 = o + nv * fz
    o5 = o4 + (L - 1) * nv * fz
    yu = y[o5:].reshape(L, nv, shape.f_u, B) if shape.f_u else None
    return TubeY(tuple(vin), y[o:o4].reshape(nv, fz, B), y[o4:o5].reshape(L - 1, nv, fz, B), yu)


def pack_y(y: TubeY, xp=np):
    """:class:`TubeY` -> flat ``(n_rows, B)``."""
    B = y.y0.shape[-1]
    return xp.concatenate([a.reshape(-1, B) for a in y.vin] + [y.y0.reshape(-1, B), y.y4.reshape(-1, B)]
                          + ([] if y.yu is None else [y.yu.reshape(-1, B)]), axis=0)


def tube_bounds(shape: TubeShape, d: TubeData, xp=np) -> tuple[TubeX, TubeX]:
    """Box bounds of ``x`` as :class:`TubeX` (``t`` bounds are ``-inf, inf``; set by the caller)."""
    B = d.lb.shape[-1]
    inf = xp.full((1, B), np.inf)
    return (unpack_x(shape, xp.concatenate([d.lb, -inf], axis=0), xp),
            unpack_x(shape, xp.concatenate([d.ub, inf], axis=0), xp))
