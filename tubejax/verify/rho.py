"""Verification of the edges' ``rho_star`` (the critical disturbance), for :mod:`tubejax.verify.verifier`.

``rho_star`` of an edge ``i -> j`` is ``max_{L <= L_max} rho*(i, j, L)`` in the units of the
file's own ``W`` (:func:`~tubejax.lp.declarations.radius_disturbance.unit_disturbance`). Always checked:
the file comes from a radius analysis (``stats.from_radius_table``), ``W`` has a radius form, and
``r <= rho_star <= rho_max`` of the target cell (a rigorous bound:
:func:`~tubejax.lp.declarations.radius_disturbance.rho_max_bound`). With ``complete`` every
``rho_star`` is re-solved with HiGHS over the horizons the candidates at ``W = {0}`` keep, to
:data:`RHO_STAR_TOL`.
"""

from __future__ import annotations

import numpy as np
from ..lp.declarations.radius_disturbance import rho_max_bound, unit_disturbance, zero_disturbance_system
from ..abstraction.candidates import build_candidates
from ..lp.evidence.radius_lp import radius_highs_optimum
from ..lp.evidence.registry import radius_forms
from ..model.problem import pair_problem

__all__ = ["RHO_STAR_TOL", "RADIUS_MARK", "check_rho_star", "check_rho_star_complete"]

#: The ``stats`` flag of a system derived from a radius table
#: (:func:`~tubejax.analyses.radius_analysis.systems.transition_system_at`): only such a file carries ``rho_star``.
RADIUS_MARK = "from_radius_table"

#: Largest difference between a stored ``rho_star`` and HiGHS's (radius units, relative to ``max(1, r)``):
#: HiGHS's own tolerances move ``rho*`` by about 1e-10.
RHO_STAR_TOL = 1e-7


def _units(ts):
    """``(W0, r)`` of the system's ``W``, or a finding."""

    try:
        return unit_disturbance(ts.system.W), ""
    except ValueError as exc:
        return None, f"rho_star: the edges carry critical disturbances but W has no radius form ({exc})"


def _where(k, e) -> str:
    return f"edges[{k}] {e.src}->{e.dst} (L={e.L})"


def check_rho_star(ts) -> list[str]:
    """The cheap checks of every edge's ``rho_star`` (``ts`` holds the rebuilt problem)."""

    ks = [k for k, e in enumerate(ts.edges) if e.rho_star is not None]
    if not ks:
        return []
    if ts.method not in radius_forms():
        return [f"rho_star: method {ts.method!r} has no radius form, yet {len(ks)} edges carry rho_star"]
    if ts.stats.get(RADIUS_MARK) is not True:
        e = ts.edges[ks[0]]
        return [f"{_where(ks[0], e)}: rho_star {e.rho_star!r} claimed ({len(ks)} of {len(ts.edges)} edges "
                f"carry one), but the file does not come from a radius analysis (stats.{RADIUS_MARK} is not "
                "true): no critical disturbance was computed for this run"]
    units, why = _units(ts)
    if units is None:
        return [why]
    (W0, r), out = units, []
    for k in ks:
        e = ts.edges[k]
        hi = rho_max_bound(ts.decomposition.cells[e.dst], W0)
        if not e.rho_star >= r:
            out.append(f"{_where(k, e)}: rho_star {e.rho_star!r} is below the file's radius {r!r} (the edge exists "
                       "at that radius, so its critical disturbance is at least that)")
        elif e.rho_star > hi:
            out.append(f"{_where(k, e)}: rho_star {e.rho_star!r} is above {hi:.9g}, the largest radius at which "
                       f"W fits in cell {e.dst}")
    return out


def check_rho_star_complete(ts, L_max: int) -> tuple[list[str], int]:
    """Re-solve every edge's ``rho_star`` with HiGHS; returns the findings and the LPs solved."""

    ks = [k for k, e in enumerate(ts.edges) if e.rho_star is not None]
    if not ks or ts.method not in radius_forms():
        return [], 0
    units, why = _units(ts)
    if units is None:
        return [why], 0
    W0, r = units
    cand = build_candidates(ts.decomposition, zero_disturbance_system(ts.system), int(L_max))
    horizons = {(int(i), int(j)): np.flatnonzero(row) + 1 for i, j, row in zip(cand.src, cand.dst, cand.keep)}
    out, n = [], 0
    for k in ks:
        e = ts.edges[k]
        best = -np.inf
        for L in horizons.get((e.src, e.dst), ()):
            prob = pair_problem(ts.decomposition, ts.system, ts.z_of(e.src, e.dst), e.src, e.dst, int(L), ts.eps_min)
            best = max(best, radius_highs_optimum(prob, ts.method, W0)[0])
            n += 1
        want = max(best, r)
        if not abs(e.rho_star - want) <= RHO_STAR_TOL * max(1.0, abs(want)):
            out.append(f"{_where(k, e)}: rho_star {e.rho_star!r} claimed, HiGHS gives {want:.12g} "
                       f"(the largest rho*(L) over L <= {L_max}, at least the file's radius)")
    return out, n
