"""The tube LP on the batched PDHG engine: the tube's :class:`~tubejax.lp.declarations.pdhg_formulation.PdhgFormulation`.

* :func:`tube_setup` stacks a group as geometry only
  (:func:`~tubejax.lp.declarations.tube_operator.build_tube_data`), starts every instance
  at the box centre with ``t`` at its own margin (a feasible point of the margin form) and
  scales on the host;
* :func:`host_tube_certificates` re-checks primal and dual points in NumPy float64 on
  the unscaled data (what the engine trusts);
* the stored evidence is HiGHS's tube (:func:`~tubejax.lp.evidence.verdict.highs_verdict`).

A non-box ``U`` stays batched (its C5 rows are the operator's hard rows); a system with a family
the operator does not model (:func:`~tubejax.lp.declarations.tube_operator_data.unmodelled_families`)
goes to HiGHS entirely.
"""

from __future__ import annotations

from typing import Sequence

import jax
import numpy as np

from ..declarations.pdhg_formulation import PdhgFormulation
from ..engines.certify import host_certificates
from ..evidence.translate_verdicts import highs_translate_verdicts
from ..evidence.verdict import highs_verdict
from .adapters import flat_ops, margin_start
from ..engines.pdhg import ScalingOperator, pdhg_init
from ...model.problem import TubeProblem
from ..declarations.tube_operator import (OperatorShape, TubeData, TubeX, TubeY, pack_x, pack_y, tube_abs_data,
                                          tube_bounds, tube_matvec, tube_rhs, tube_rmatvec, tube_square_data, unpack_x,
                                          unpack_y)
from ..declarations.tube_operator_data import build_tube_data, facet_counts, unmodelled_families, vertex_families

__all__ = ["TUBE_PDHG", "tube_setup", "tube_flat_ops", "host_tube_certificates"]


def tube_flat_ops(shape: OperatorShape, xp):
    """:func:`~tubejax.lp.batch.adapters.flat_ops` for the tube operator."""
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


def host_tube_certificates(shape: OperatorShape, data: TubeData, z: TubeX,
                           y: TubeY) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~tubejax.lp.engines.certify.host_certificates` of the tube operator (pytree points)."""
    data, z, y = jax.tree_util.tree_map(lambda a: np.asarray(a, float), (data, z, y))
    return host_certificates((tube_matvec, tube_rmatvec, tube_rhs, tube_bounds), shape, data, z, y)


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
