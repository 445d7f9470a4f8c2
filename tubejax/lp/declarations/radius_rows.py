"""The rows of each LP's radius-parametric form (docs/math/radius.md), and its reference point.

With ``W = rho W_0`` every disturbance term is linear in ``rho``. A :class:`~.formulation.RadiusForm` (the
``radius`` of an LP's :class:`~tubejax.lp.declarations.formulation.Formulation`) holds its dense rows
at ``rho = 0``, ``rho``'s column and a reference point; the radius LP and its solvers read it.
"""

from __future__ import annotations

import numpy as np

from ...model.geometry import Ball, support
from ...model.problem import TubeProblem
from .openloop_lp import OpenLoopIndex, openloop_lp_column
from .radius_disturbance import with_disturbance
from .row_families import families_in
from .tube_families import TUBE_FAMILIES, float_terms
from .tube_lp import build_tube_lp
from .tube_variables import TubeIndex

__all__ = ["tube_radius_rows", "tube_radius_reference", "openloop_radius_rows",
           "openloop_radius_reference"]


def tube_radius_reference(problem: TubeProblem, L: int | None = None) -> np.ndarray:
    """``p_l`` at the vertex mean of ``S``, ``p_L`` at that of ``P_j``, ``eps = eps_min``, ``u = 0``.

    Parameters
    ----------
    problem : TubeProblem
        The instance; ``p_L`` sits at its own horizon ``problem.L``.
    L : int, optional
        The horizon of the layout, ``>= problem.L`` (the batched engine's padded one); the steps past
        ``problem.L`` take the vertex mean of ``S``. Default ``problem.L``.

    Returns
    -------
    np.ndarray, shape ``(n_x,)``
        The point in ``build_tube_lp``'s column layout at horizon ``L``.
    """
    sysm, own = problem.system, int(problem.L)
    L = own if L is None else L
    ix = TubeIndex(L, sysm.n, problem.source.n_vertices, sysm.m)
    p = np.repeat(problem.safe.vertices.mean(axis=0)[None], L, axis=0)
    p[own - 1] = problem.target.vertices.mean(axis=0)
    x = np.zeros(ix.size)
    x[ix.p] = p.ravel()
    x[ix.eps] = float(problem.eps_min)
    return x


def openloop_radius_reference(problem: TubeProblem) -> np.ndarray:
    """``u = 0`` (strictly inside every ``U``: :class:`~tubejax.model.system.LinearSystem` requires it)."""
    return np.zeros(OpenLoopIndex(int(problem.L), problem.source.n_vertices, problem.system.m).size)


def tube_radius_rows(problem: TubeProblem, W0):
    """Rows at ``rho = 0`` (``W = {0}``: rhs and bounds without the disturbance) and ``c``: in the
    rows of each family that ``sigma_W`` enters (:attr:`~tubejax.lp.declarations.row_families.RowFamily.disturbed`: C4),
    ``sigma_{W_0}`` of the row's unit state-space normal, found by the family's name."""
    free = with_disturbance(problem, Ball(problem.system.n, 0.0))
    lp, d = build_tube_lp(free), float_terms(free)
    c = np.zeros(lp.G.shape[0])
    for f in families_in(TUBE_FAMILIES, d):
        if f.disturbed and f.name in lp.layout.names:
            unit = f.normals(d) / np.linalg.norm(f.normals(d), axis=1)[:, None]      # as the LP's rows
            c[lp.layout.slice(f.name)] = np.broadcast_to(support(W0, unit), lp.layout.shape(f.name)).ravel()
    return lp, c


def openloop_radius_rows(problem: TubeProblem, W0):
    """The open-loop rows at ``rho = 0`` and ``c``, ``sigma_{D_l}`` of ``W0`` row by row
    (:func:`~tubejax.lp.declarations.openloop_lp.openloop_lp_column`)."""
    return openloop_lp_column(problem, W0)
