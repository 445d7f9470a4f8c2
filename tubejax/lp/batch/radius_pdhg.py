"""The radius form (docs/math/radius.md) on the one batched PDHG engine: :data:`RADIUS_TUBE_PDHG`,
:data:`RADIUS_OPENLOOP_PDHG`.

They reuse the margin form's operators in their ``'radius'`` form (``t``'s all-ones column becomes
``rho``'s coefficients) and run in the optimise mode (:func:`radius_pdhg_solver`): per instance an
estimate of ``rho*``, a rigorous upper bound, a lower estimate
(:mod:`tubejax.lp.engines.objective_bounds`), the status and the primal point. Bounds, ``rho_min``,
``rho_max`` and the reference point are those of :mod:`~tubejax.lp.evidence.radius_lp`. A group is
one system (any radius of one shape shares the executables). A non-box ``U``'s rows are hard rows
(no ``rho``; the reference ``u = 0`` satisfies them strictly). Problems with a family an operator
does not model, or whose reference point violates C2 / C3 (only with ``eps_min > 0``), go to HiGHS.
"""

from __future__ import annotations

from functools import partial
from typing import Callable, NamedTuple, Sequence

import numpy as np

from ..declarations.pdhg_formulation import PdhgFormulation
from ..evidence.registry import FORMULATIONS, radius_forms
from .adapters import objective_column, radius_adapter
from .openloop_pdhg import OPENLOOP_PDHG
from .tube_pdhg import tube_flat_ops
from ..engines.objective_bounds import ObjectiveRef
from .batch_solver import PdhgBatchSolver
from .optimise_mode import host_objective_certificates
from ..engines.pdhg import PdhgOptions, PdhgProblem, ScalingOperator, pdhg_init
from ..declarations import openloop_operator as olop
from ..declarations.openloop_operator import openloop_coef_data, openloop_coef_ops
from ..declarations.openloop_operator_data import build_openloop_data
from ..declarations import tube_operator as tbop
from ..declarations.tube_lp import Tube
from ...model.problem import TubeProblem
from ..declarations.tube_operator_data import build_tube_data, facet_counts, unmodelled_families
from ..declarations.openloop_lp import OpenLoopPlan
from ..evidence.radius_lp import radius_highs_optimum
from ..declarations.radius_disturbance import rho_max_bound, unit_disturbance

__all__ = ["RADIUS_TUBE_PDHG", "RADIUS_OPENLOOP_PDHG", "radius_pdhg_solver", "RADIUS_OPTIONS"]

#: Defaults of :func:`radius_pdhg_solver`: the optimise mode, a duality gap of 1e-4 in radius
#: units (rho* to about four decimals on unit cells; a requested radius within the gap of rho* is
#: HiGHS's to decide anyway), a high cap and a check every 8 iterations
#: (docs/explanation/performance.md#radius-optimise-mode).
RADIUS_OPTIONS = PdhgOptions(mode="optimise", gap_tol=1e-4, max_iters=4096, check_every=8, checks_per_call=16)


def _reference(mv, data, g, mask, x_ref):
    """The flat :class:`~tubejax.lp.engines.objective_bounds.ObjectiveRef` of ``x_ref`` (``(n_x + 1, B)``)
    and the largest ``rho`` at which ``x_ref`` satisfies every row with a ``rho`` coefficient, ``(B,)``."""
    col = mv(data, np.zeros_like(x_ref) + np.eye(x_ref.shape[0])[:, -1:])     # rho's column
    rows = mv(data, x_ref) - g
    soft = (mask > 0) & (col > 0)
    rho_ref = np.min(np.where(soft, -rows / np.where(soft, col, 1.0), np.inf), axis=0)
    return ObjectiveRef(x_ref, col, rows), rho_ref


class RadiusGroup(NamedTuple):
    """One group's flat host problem at ``rho = 0`` (batch axis last) and what scales it.

    Attributes
    ----------
    data : the operator's host data (its ``lean()`` copy goes to the device)
    g, mask : ``(n_rows, B)``: right-hand sides and row mask
    lo, hi : ``(n_x + 1, B)``: bounds (``rho``'s, the last, are set by :func:`_finish`)
    x_ref : ``(n_x + 1, B)``: the reference point (:func:`~tubejax.lp.evidence.radius_lp.radius_reference`)
    mv : the flat matvec     scale_ops : ``(matvec, rmatvec)`` on ``abs_data`` / ``sq_data``
    abs_data, sq_data : ``|K|`` and ``K o K`` data (the scaling's)
    """

    data: object
    g: np.ndarray
    mask: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    x_ref: np.ndarray
    mv: Callable
    scale_ops: tuple
    abs_data: object
    sq_data: object


def _finish(group: RadiusGroup, options, probs):
    """The host and device problems of ``group`` and the state scaled with its ``scale_ops`` on
    ``|K|`` / ``K o K`` data, started at ``x_ref`` with ``rho = rho_ref``.
    ``rho``'s bounds: ``rho_max`` (:func:`rho_max_bound` of the target) and
    ``rho_min = min(rho_ref, 0) - rho_max``, as in :func:`~tubejax.lp.evidence.radius_lp.build_radius_lp`."""
    g, mask, x_ref = np.ascontiguousarray(group.g), np.ascontiguousarray(group.mask), group.x_ref
    ref, rho_ref = _reference(group.mv, group.data, g, mask, x_ref)
    W0 = unit_disturbance(probs[0].system.W)[0]
    hi_t = np.array([rho_max_bound(p.target, W0) for p in probs])
    lo_t = np.minimum(rho_ref, 0.0) - hi_t
    c, lo, hi, z0 = objective_column(group.lo, group.hi, x_ref, lo_t, hi_t, np.clip(rho_ref, lo_t, hi_t))
    host = PdhgProblem(group.data, c, g, lo, hi, mask, ref)
    state = pdhg_init(ScalingOperator(*group.scale_ops, group.abs_data, group.sq_data), host, z0, options, np)
    return host, host._replace(data=group.data.lean()), state


# ----------------------------------------------------------------------------- tube
_tube_ops = tube_flat_ops                      # the margin form's operator, in its 'radius' form


def radius_tube_setup(probs: Sequence[TubeProblem], L_pad: int, f_v: tuple, options,
                      share: bool = True):
    """``(shape, host_problem, device_problem, state)`` of one group of the radius tube LP."""
    W0 = unit_disturbance(probs[0].system.W)[0]
    shape, data = build_tube_data(probs, f_v=f_v, L_pad=L_pad, share=share, W0=W0)
    g, mask = tbop.tube_rhs(shape, data, np)
    lo, hi = tbop.tube_bounds(shape, data, np)
    B, L = len(probs), shape.L
    own = np.array([int(p.L) for p in probs])
    cs = np.stack([p.safe.vertices.mean(axis=0) for p in probs], axis=-1)          # (n, B)
    ct = np.stack([p.target.vertices.mean(axis=0) for p in probs], axis=-1)
    p_ref = np.where((np.arange(1, L + 1)[:, None] == own[None, :])[:, None, :], ct[None], cs[None])
    eps_ref = np.broadcast_to(np.array([float(p.eps_min) for p in probs]), (L, B)) + 0.0
    x_ref = tbop.pack_x(tbop.TubeX(p_ref, eps_ref, np.zeros(lo.u0.shape), np.zeros(lo.u.shape),
                                   np.zeros(B)))
    mv, rmv, _ = _tube_ops(shape, np)
    group = RadiusGroup(data, tbop.pack_y(g), tbop.pack_y(mask), tbop.pack_x(lo), tbop.pack_x(hi),
                        x_ref, mv, (mv, rmv), tbop.tube_abs_data(data, np), tbop.tube_square_data(data, np))
    return (shape, *_finish(group, options, probs))


def _tube_point(shape, z, problem: TubeProblem) -> Tube:
    x = tbop.unpack_x(shape, np.asarray(z, float)[:, None])
    L = int(problem.L)
    u = np.concatenate([x.u0[None], x.u], axis=0)[:L, ..., 0]
    return Tube(x.p[:L, :, 0].copy(), x.eps[:L, 0].copy(), u)


def _tube_batched(p: TubeProblem) -> bool:
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


# ----------------------------------------------------------------------------- open loop
_openloop_ops = OPENLOOP_PDHG.ops              # the margin form's operator, in its 'radius' form


def radius_openloop_setup(probs: Sequence[TubeProblem], L_pad: int, f_pad: tuple, options,
                          share: bool = True):
    """``(shape, host_problem, device_problem, state)`` of one group of the radius open-loop LP."""
    W0 = unit_disturbance(probs[0].system.W)[0]
    f_s, f_t = f_pad
    shape, data = build_openloop_data(probs, L_pad=L_pad, f_s=f_s, f_t=f_t, W0=W0)
    g, mask = olop.openloop_rhs(shape, data)
    lo, hi = olop.openloop_bounds(shape, data)
    x_ref = olop.pack_x(olop.OpenLoopX(np.zeros(lo.u.shape), np.zeros(len(probs))))
    coef = openloop_coef_data(shape, data)
    group = RadiusGroup(data, olop.pack_y(g), olop.pack_y(mask), olop.pack_x(lo), olop.pack_x(hi),
                        x_ref, _openloop_ops(shape, np)[0], openloop_coef_ops(shape), coef.apply(np.abs),
                        coef.apply(np.square))
    return (shape, *_finish(group, options, probs))


def _openloop_point(shape, z, problem: TubeProblem) -> OpenLoopPlan:
    x = olop.unpack_x(shape, np.asarray(z, float)[:, None])
    return OpenLoopPlan(x.u[:int(problem.L), ..., 0].copy())


def _tube_key(p: TubeProblem):
    return (p.source.n_vertices, p.Z.H.shape[0], p.system.n), id(p.system)


#: The radius form of the tube LP on the batched engine (optimise mode only: ``verdict`` is None;
#: ``certificates`` take the host problem that ``setup`` returns as its data).
RADIUS_TUBE_PDHG = PdhgFormulation("radius-tube", _tube_key, facet_counts, radius_tube_setup, _tube_ops,
                                   partial(host_objective_certificates, _tube_ops), None, _tube_batched,
                                   partial(radius_highs_optimum, form="tube"), _tube_point)
#: The radius form of the open-loop LP on the batched engine: the open-loop adapter's groups, facet counts,
#: operator and choice of the batched path (every family modelled; the reference ``u = 0`` is strictly
#: inside every row).
RADIUS_OPENLOOP_PDHG = PdhgFormulation("radius-openloop", OPENLOOP_PDHG.group_key, OPENLOOP_PDHG.facet_counts,
                                       radius_openloop_setup, _openloop_ops,
                                       partial(host_objective_certificates, _openloop_ops), None,
                                       OPENLOOP_PDHG.batched, partial(radius_highs_optimum, form="openloop"),
                                       _openloop_point)


def radius_pdhg_solver(form: str = "tube", options: PdhgOptions | None = None, **kw) -> PdhgBatchSolver:
    """The batched engine on the radius form: call ``.radius.optimise(problems)``.

    Parameters
    ----------
    form : str
        An LP whose record has a batched radius form (``'tube'``, ``'openloop'``:
        :func:`~tubejax.lp.batch.adapters.radius_adapter`).
    options : PdhgOptions, optional
        Default :data:`RADIUS_OPTIONS`; ``**kw`` override its fields or set
        :class:`~tubejax.lp.batch.batch_solver.PdhgBatchSolver` arguments.

    Raises
    ------
    ValueError
        ``form`` has no batched radius form (the message lists those that have one).
    """
    record = FORMULATIONS.get(form) if isinstance(form, str) else None
    fm = None if record is None else radius_adapter(record)
    if fm is None:
        raise ValueError(f"form: expected one of {radius_forms()}, got {form!r}")
    return PdhgBatchSolver(options=options or RADIUS_OPTIONS, formulation=fm, **kw)
