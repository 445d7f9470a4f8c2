"""The tube LP on the batched PDHG engine: its :class:`~tubejax.lp.declarations.formulation.PdhgForm`
for sign decisions (:data:`TUBE_PDHG`) and for its radius form's optima (:data:`RADIUS_TUBE_PDHG`).

:func:`tube_setup` stacks a group as geometry only
(:func:`~tubejax.lp.declarations.tube_operator_data.build_tube_data`), starts each instance at the box
centre with ``t`` at its own margin (feasible) and scales on the host; certificates are re-checked
in float64 on the unscaled data (:func:`~tubejax.lp.engines.pdhg_adapters.host_flat_certificates`),
all derived from :data:`~tubejax.lp.declarations.tube_operator.TUBE_OPERATOR`.
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
from .pdhg_adapters import flat_ops, host_flat_certificates, margin_setup, radius_setup
from ...model.problem import TubeProblem
from ..declarations.tube_variables import Tube
from ..declarations.tube_operator import TUBE_OPERATOR, TubeX, unpack_x
from ..declarations.tube_operator_data import build_tube_data, facet_counts, unmodelled_families, vertex_families

__all__ = ["TUBE_PDHG", "RADIUS_TUBE_PDHG", "tube_setup", "radius_tube_setup"]

#: :func:`~tubejax.lp.engines.pdhg_adapters.flat_ops` of the tube operator: ``ops(shape, xp)``.
_flat_ops = partial(flat_ops, TUBE_OPERATOR)


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
    return margin_setup(TUBE_OPERATOR, shape, data, options, state_dim=shape.n)


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
TUBE_PDHG = PdhgForm(_group_key, facet_counts, tube_setup, _flat_ops, partial(host_flat_certificates, TUBE_OPERATOR),
                     _batched, translates=True, dual_key=_dual_key)


# ----------------------------------------------------------------------------- the radius form
def radius_tube_setup(probs: Sequence[TubeProblem], L_pad: int, f_v: tuple, options,
                      share: bool = True):
    """``(shape, host_problem, device_problem, state)`` of one group of the radius tube LP, started at the
    reference point (:func:`~tubejax.lp.declarations.radius_rows.tube_radius_reference`)."""
    W0 = unit_disturbance(probs[0].system.W)[0]
    shape, data = build_tube_data(probs, f_v=f_v, L_pad=L_pad, share=share, W0=W0)
    B, L, nv, m = len(probs), shape.L, shape.n_v, shape.m
    own = np.array([int(p.L) for p in probs])
    cs = np.stack([p.safe.vertices.mean(axis=0) for p in probs], axis=-1)          # (n, B)
    ct = np.stack([p.target.vertices.mean(axis=0) for p in probs], axis=-1)
    p_ref = np.where((np.arange(1, L + 1)[:, None] == own[None, :])[:, None, :], ct[None], cs[None])
    eps_ref = np.broadcast_to(np.array([float(p.eps_min) for p in probs]), (L, B)) + 0.0
    x_ref = TubeX(p_ref, eps_ref, np.zeros((nv, m, B)), np.zeros((L - 1, nv, m, B)), np.zeros(B))
    return radius_setup(TUBE_OPERATOR, shape, data, x_ref, options, probs)


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
RADIUS_TUBE_PDHG = PdhgForm(_radius_key, facet_counts, radius_tube_setup, _flat_ops,
                            partial(host_objective_certificates, _flat_ops), _radius_batched, radius=True,
                            point=_radius_point)
