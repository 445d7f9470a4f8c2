"""An LP's adapters to the batched PDHG engine, reached through its record.

A :class:`~tubejax.lp.declarations.formulation.Formulation` lives below this layer (in
:mod:`tubejax.lp.evidence.records`), so it names its adapters -- ``pdhg`` for sign decisions,
``radius.pdhg`` for the radius form's optimise mode -- as ``'module:NAME'`` of this package, and
this module imports them on first use. Nothing here is written per method: a new LP with a
batched form names its adapter in its record, and its adapter derives the flat operator and the
feasible start from its operator (:func:`flat_ops`, :func:`margin_start`).
"""

from __future__ import annotations

import importlib

import jax
import numpy as np

from ..declarations.formulation import Formulation
from ..declarations.pdhg_formulation import PdhgFormulation
from ..engines.certify import make_margin_certify
from ..engines.pdhg import PdhgProblem

__all__ = ["pdhg_adapter", "radius_adapter", "flat_ops", "margin_start", "objective_column"]


def _resolve(ref: str) -> PdhgFormulation:
    module, name = ref.split(":")
    return getattr(importlib.import_module(f"{__package__}.{module}"), name)


def pdhg_adapter(record: Formulation) -> PdhgFormulation | None:
    """The batched PDHG form of ``record``'s LP (``record.pdhg``), or ``None`` when it has none."""
    return None if record.pdhg is None else _resolve(record.pdhg)


def radius_adapter(record: Formulation) -> PdhgFormulation | None:
    """The batched PDHG form of ``record``'s radius LP (``record.radius.pdhg``), or ``None``."""
    radius = record.radius
    return None if radius is None or radius.pdhg is None else _resolve(radius.pdhg)


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
