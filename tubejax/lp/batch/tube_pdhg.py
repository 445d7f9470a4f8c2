"""The tube LP on the batched PDHG engine: the tube's :class:`~tubejax.lp.declarations.pdhg_formulation.PdhgFormulation`.

* :func:`tube_setup` stacks a group as geometry only
  (:func:`~tubejax.lp.declarations.tube_operator.build_tube_data`), starts every instance
  at the box centre with ``t`` at its own margin (a feasible point of the margin form) and
  scales on the host;
* :func:`host_tube_certificates` re-checks primal and dual points in NumPy float64 on
  the unscaled data (what the engine trusts);
* the stored evidence is HiGHS's tube (:func:`~tubejax.lp.evidence.verdict.highs_verdict`).

Systems with a family the operator does not model (:func:`~tubejax.lp.declarations.tube_operator_data.unmodelled_families`:
hard rows such as ``C5`` of a non-box ``U``) go to HiGHS entirely.
"""

from __future__ import annotations

from typing import Sequence

import jax
import numpy as np

from ..declarations.pdhg_formulation import PdhgFormulation
from ..engines.certify import dual_bound, primal_violation
from ..evidence.translate_verdicts import highs_translate_verdicts
from ..evidence.verdict import highs_verdict
from ..engines.pdhg import PdhgProblem, ScalingOperator, flat_ops, pdhg_init
from ...model.problem import TubeProblem
from ..declarations.tube_operator import (TubeData, TubeShape, TubeX, TubeY, pack_x, pack_y, tube_abs_data, tube_bounds,
                                          tube_matvec, tube_rhs, tube_rmatvec, tube_square_data, unpack_x, unpack_y)
from ..declarations.tube_operator_data import build_tube_data, facet_counts, unmodelled_families, vertex_families

__all__ = ["TUBE_PDHG", "tube_setup", "tube_flat_ops", "host_tube_certificates"]

_T_MAX = 1.0


def tube_start(shape: TubeShape, data, xp=np):
    """Margin-form problem pytrees and a feasible start: ``x`` = box centre, ``t`` = its margin."""
    g, mask = tube_rhs(shape, data, xp)
    lo, hi = tube_bounds(shape, data, xp)
    B = g.y0.shape[-1]
    zero = xp.zeros((B,))
    x_mid = jax.tree_util.tree_map(lambda a, b: 0.5 * (a + b), lo._replace(t=zero), hi._replace(t=zero))
    kx = tube_matvec(shape, data, x_mid, xp)
    t0 = xp.min(xp.stack([xp.min(xp.where(m > 0, gi - k, xp.inf).reshape(-1, B), axis=0, initial=np.inf)
                          for gi, k, m in zip(*map(jax.tree_util.tree_leaves, (g, kx, mask)))]),
                 axis=0)                                                          # t* >= t0
    lo = lo._replace(t=xp.minimum(t0, 0.0) - 1.0)
    hi = hi._replace(t=xp.full((B,), _T_MAX))
    z0 = x_mid._replace(t=xp.minimum(t0, _T_MAX))
    c = jax.tree_util.tree_map(xp.zeros_like, z0)._replace(t=xp.full((B,), -1.0))
    g = jax.tree_util.tree_map(lambda a: xp.ascontiguousarray(a), g)
    mask = jax.tree_util.tree_map(lambda a: xp.ascontiguousarray(a), mask)
    return PdhgProblem(data, c, g, lo, hi, mask), z0


def tube_flat_ops(shape: TubeShape, xp):
    """:func:`~tubejax.lp.engines.pdhg.flat_ops` for the tube operator."""
    return flat_ops(shape, xp, tube_matvec, tube_rmatvec, pack_x, unpack_x, pack_y, unpack_y)


def tube_setup(probs: Sequence[TubeProblem], L_pad: int, f_v: tuple, options, share: bool = True):
    """``(shape, data, prob, state)`` of one shape group, scaled on the host.

    Parameters
    ----------
    probs : sequence of TubeProblem, one shape group (``B`` problems)
    L_pad : int
        Padded horizon.
    f_v : tuple of int
        Padded facet counts of the ``VertexIn`` families (:func:`~tubejax.lp.declarations.tube_operator_data.facet_counts`).
    options : PdhgOptions
    share : bool
        Store coefficients shared by every instance once (``build_tube_data``).
    """
    shape, data = build_tube_data(probs, f_v=f_v, L_pad=L_pad, share=share)
    prob, z0 = tube_start(shape, data, np)
    # the device copy drops what K never reads (rhs and bounds live in prob.g / lo / hi)
    lean = data.lean()
    prob = PdhgProblem(lean, pack_x(prob.c), pack_y(prob.g), pack_x(prob.lo), pack_x(prob.hi),
                       pack_y(prob.mask))
    mv, rmv, _ = tube_flat_ops(shape, np)
    op = ScalingOperator(mv, rmv, tube_abs_data(data, np), tube_square_data(data, np))
    state = pdhg_init(op, prob, pack_x(z0), options, np, state_dim=shape.n)
    return shape, data, prob, state


def host_tube_certificates(shape: TubeShape, data: TubeData, z: TubeX,
                           y: TubeY) -> tuple[np.ndarray, np.ndarray]:
    """Re-check certificates in NumPy float64 from the unscaled tube data.

    Parameters
    ----------
    shape : TubeShape
    data : TubeData, NumPy arrays, batch axis last (``B``)
    z : TubeX primal points     y : TubeY dual points (batch axis last)

    Returns
    -------
    viol, bound : (B,) each -- the largest violation of Problem 2 by ``z`` (``t = 0``)
    and the rigorous upper bound on ``t*`` given by ``y``
    """
    data, z, y = jax.tree_util.tree_map(lambda a: np.asarray(a, float), (data, z, y))
    g, mask = tube_rhs(shape, data, np)
    lo, hi = tube_bounds(shape, data, np)
    mv = lambda d, v: tube_matvec(shape, d, v, np)          # noqa: E731
    rmv = lambda d, v: tube_rmatvec(shape, d, v, np)        # noqa: E731
    viol = primal_violation(mv, data, g, mask, lo, hi, z, np)
    bound = dual_bound(rmv, data, g, mask, lo, hi, y, np)
    return np.asarray(viol), np.asarray(bound)


def _host_flat_certificates(shape, data, z, y):
    """:func:`host_tube_certificates` of flat ``(n, B)`` points."""
    return host_tube_certificates(shape, data, unpack_x(shape, z), unpack_y(shape, y))


def _group_key(p: TubeProblem):
    # the static shape names its VertexIn families: their facet counts are padded per family
    families = tuple(f.name for f in vertex_families(p.system))
    return (p.source.n_vertices, p.Z.H.shape[0], p.system.n, families), id(p.system)


def _dual_key(p: TubeProblem):
    # the same horizon, offset between the cells, case (facets of S) and Z: the same rows up to
    # the right-hand side on a grid (pairs that differ by a translation A does not fix)
    offset = np.round(p.target.centroid - p.source.centroid, 9) + 0.0
    return int(p.L), offset.tobytes(), p.safe.H.shape[0], p.Z.H.tobytes()


def _batched(p: TubeProblem) -> bool:
    return not unmodelled_families(p.system)


#: The tube LP on the batched engine (the default of ``PdhgBatchSolver``).
TUBE_PDHG = PdhgFormulation("tube", _group_key, facet_counts, tube_setup, tube_flat_ops,
                            _host_flat_certificates, highs_verdict, _batched,
                            verdicts=highs_translate_verdicts, dual_key=_dual_key)
