"""The tube LP on the batched PDHG engine: its :class:`~tubejax.lp.declarations.formulation.PdhgForm`
for sign decisions (:data:`TUBE_PDHG`) and for its radius form's optima (:data:`RADIUS_TUBE_PDHG`).

:func:`tube_setup` stacks a group as geometry only
(:func:`~tubejax.lp.declarations.tube_operator_data.build_tube_data`), starts each instance at the box
centre with ``t`` at its own margin (feasible) and scales on the host; certificates are re-checked
in float64 on the unscaled data (:func:`~tubejax.lp.engines.pdhg_adapters.host_flat_certificates`).
The stored evidence is HiGHS's tube. A family the operator does not model
(:func:`~tubejax.lp.declarations.tube_operator_data.unmodelled_families`) sends the system to HiGHS.
The radius form (docs/math/radius.md) uses the operator's ``'radius'`` form in optimise mode.
"""

from __future__ import annotations

from functools import partial
from typing import Sequence

import numpy as np

from ..declarations.formulation import PdhgForm
from ..declarations.radius_disturbance import unit_disturbance
from .objective_bounds import host_objective_certificates
from .pdhg_adapters import RadiusGroup, flat_ops, host_flat_certificates, margin_start, radius_start
from .pdhg import ScalingOperator, pdhg_init
from ...model.problem import TubeProblem
from ..declarations.tube_variables import Tube
from ..declarations.tube_operator import (OperatorShape, TubeX, pack_x, pack_y, tube_abs_data, tube_bounds,
                                          tube_matvec, tube_rhs, tube_rmatvec, tube_square_data, unpack_x, unpack_y)
from ..declarations.tube_operator_data import build_tube_data, facet_counts, unmodelled_families, vertex_families

__all__ = ["TUBE_PDHG", "RADIUS_TUBE_PDHG", "tube_setup", "tube_flat_ops", "radius_tube_setup"]


def tube_flat_ops(shape: OperatorShape, xp):
    """:func:`~tubejax.lp.engines.pdhg_adapters.flat_ops` for the tube operator."""
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
    prob, z0 = margin_start((tube_matvec, tube_rhs, tube_bounds), (pack_x, pack_y), shape, data)
    mv, rmv, _ = tube_flat_ops(shape, np)
    op = ScalingOperator(mv, rmv, tube_abs_data(data, np), tube_square_data(data, np))
    state = pdhg_init(op, prob, z0, options, np, state_dim=shape.n)
    return shape, data, prob, state


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


#: The tube LP on the batched engine (its record's ``pdhg``; the default of ``PdhgBatchSolver``).
TUBE_PDHG = PdhgForm(_group_key, facet_counts, tube_setup, tube_flat_ops,
                     partial(host_flat_certificates, (tube_matvec, tube_rmatvec, tube_rhs, tube_bounds),
                             (unpack_x, unpack_y)),
                     _batched, translates=True, dual_key=_dual_key)


# ----------------------------------------------------------------------------- the radius form
def radius_tube_setup(probs: Sequence[TubeProblem], L_pad: int, f_v: tuple, options,
                      share: bool = True):
    """``(shape, host_problem, device_problem, state)`` of one group of the radius tube LP, started at the
    reference point (:func:`~tubejax.lp.declarations.radius_rows.tube_radius_reference`)."""
    W0 = unit_disturbance(probs[0].system.W)[0]
    shape, data = build_tube_data(probs, f_v=f_v, L_pad=L_pad, share=share, W0=W0)
    g, mask = tube_rhs(shape, data, np)
    lo, hi = tube_bounds(shape, data, np)
    B, L = len(probs), shape.L
    own = np.array([int(p.L) for p in probs])
    cs = np.stack([p.safe.vertices.mean(axis=0) for p in probs], axis=-1)          # (n, B)
    ct = np.stack([p.target.vertices.mean(axis=0) for p in probs], axis=-1)
    p_ref = np.where((np.arange(1, L + 1)[:, None] == own[None, :])[:, None, :], ct[None], cs[None])
    eps_ref = np.broadcast_to(np.array([float(p.eps_min) for p in probs]), (L, B)) + 0.0
    x_ref = pack_x(TubeX(p_ref, eps_ref, np.zeros(lo.u0.shape), np.zeros(lo.u.shape), np.zeros(B)))
    mv, rmv, _ = tube_flat_ops(shape, np)
    group = RadiusGroup(data, pack_y(g), pack_y(mask), pack_x(lo), pack_x(hi), x_ref, mv, (mv, rmv),
                        tube_abs_data(data, np), tube_square_data(data, np))
    return (shape, *radius_start(group, options, probs))


def _radius_point(shape, z, problem: TubeProblem) -> Tube:
    x = unpack_x(shape, np.asarray(z, float)[:, None])
    L = int(problem.L)
    u = np.concatenate([x.u0[None], x.u], axis=0)[:L, ..., 0]
    return Tube(x.p[:L, :, 0].copy(), x.eps[:L, 0].copy(), u)


def _radius_batched(p: TubeProblem) -> bool:
    """Every family modelled by the operator (:func:`~tubejax.lp.declarations.tube_operator_data.unmodelled_families`,
    the hard rows of a non-box ``U`` included) and a reference point strictly inside C2 / C3 (with
    ``eps_min = 0`` the reference is the vertex mean of a full-dimensional polytope: interior)."""
    if unmodelled_families(p.system):
        return False
    e = float(p.eps_min)
    if e == 0.0:
        return True
    for P in (p.safe, p.target):
        if np.any(P.H @ P.vertices.mean(axis=0) + e * p.Z.support(P.H) - P.h >= 0):
            return False
    return True


def _radius_key(p: TubeProblem):
    return (p.source.n_vertices, p.Z.H.shape[0], p.system.n), id(p.system)


#: The radius form of the tube LP on the batched engine (optimise mode only;
#: ``certificates`` take the host problem that ``setup`` returns as its data).
RADIUS_TUBE_PDHG = PdhgForm(_radius_key, facet_counts, radius_tube_setup, tube_flat_ops,
                            partial(host_objective_certificates, tube_flat_ops), _radius_batched, radius=True,
                            point=_radius_point)
