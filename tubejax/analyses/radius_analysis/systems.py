"""The verified transition system at a requested radius, derived from a :class:`RadiusTable`.

Algorithm 2's result at ``W = rho W_0`` is, per pair, the smallest ``L <= L_max`` with
``rho*(i, j, L) >= rho``. :func:`transition_system_at` decides each instance with evidence, never
with the estimate alone (docs/math/radius.md#evidence-at-a-radius): a non-edge by the rigorous dual
bound ``upper < rho - tie_tol`` or a negative HiGHS margin at ``W = rho W_0``; an edge by HiGHS's tube
at that radius, re-checked in float64 and proved exactly (:meth:`TransitionSystem.prove`); a ``rho``
within ``tie_tol`` of the bracket goes to HiGHS. Horizons are tried in increasing order, one per
pair and round (one HiGHS batch per round), and a pair stops at its first edge, so the result is
Algorithm 2's. Each edge carries ``rho_star`` (exact: :meth:`RadiusTable.refine`).
"""

from __future__ import annotations

import dataclasses
import time
from collections import Counter
from functools import partial
from typing import NamedTuple

import numpy as np

from ...model.geometry import Ball, support
from ...lp.evidence.verdict import highs_verdict
from ...lp.evidence.registry import formulation
from ...lp.declarations.radius_disturbance import scaled_disturbance, unit_disturbance
from ...model.system import LinearSystem
from ...transitions.transition_system import Edge, TransitionSystem
from .radius_table import RHO_TIE_TOL, RadiusTable, highs_map
from ...abstraction.rounds import ZERO_MARGIN_TOL

__all__ = ["RHO_TIE_TOL", "transition_system_at", "check_scaled_disturbance", "n_edges_vs_L_max"]

#: Relative tolerance of :func:`check_scaled_disturbance`.
_SCALE_RTOL = 1e-12


def check_scaled_disturbance(W, W0, rho: float) -> None:
    """Raise ``ValueError`` unless ``sigma_W = rho sigma_{W0}`` (checked on the axes, their
    negatives and the diagonals, to ``1e-12`` relative)."""
    n = W0.dim
    if W.dim != n:
        raise ValueError(f"the disturbance is {W.dim}-D, expected {n}-D")
    eye = np.eye(n)
    D = np.vstack([eye, -eye, np.ones((1, n)), -np.ones((1, n))])
    a, b = support(W, D), rho * support(W0, D)
    if not np.allclose(a, b, rtol=_SCALE_RTOL, atol=_SCALE_RTOL * max(1.0, float(np.max(np.abs(b))))):
        raise ValueError(f"the system's W is not {rho!r} W0 (support values {np.round(a, 12).tolist()} "
                         f"against {np.round(b, 12).tolist()})")


def _file_units(W, W0, rho: float) -> tuple[float, float]:
    """``(radius in the file's units, factor from W0 units to the file's)``: ``rho_star`` is
    stored in the units of :func:`unit_disturbance` of the saved system's own ``W``."""
    if rho == 0.0:
        if not isinstance(W0, Ball):
            raise ValueError("the radius 0 of a polytope W0 gives W = {0}, which the saved system can only "
                             "state as a ball: its rho_star would be in other units; use a radius > 0")
        return 0.0, 1.0
    r_file = unit_disturbance(W)[1]
    return r_file, r_file / rho


def transition_system_at(table: RadiusTable, rho: float, system: LinearSystem | None = None, *,
                         L_max: int | None = None, workers=None, tie_tol: float = RHO_TIE_TOL,
                         prove: bool = True) -> TransitionSystem:
    """The verified transition system of ``table``'s form at ``W = rho W_0`` (see the module docstring).

    Parameters
    ----------
    table : RadiusTable
    rho : float, ``>= 0``
        In ``table.W0``'s units (a ball's radius, a cube's half-width, a polytope's scale).
    system : LinearSystem, optional
        The system at that radius (default: ``table.system`` with ``W = rho W_0``); its ``W``
        must be ``rho W_0`` (:func:`check_scaled_disturbance`). The app passes the system
        built from the inputs record that it saves, so that verification rebuilds it exactly.
    L_max : int, optional
        At most the table's (default): the system for every smaller ``L_max`` comes from the
        same table.
    workers : ProcessWorkers, optional
        Where half of the HiGHS solves run.
    prove : bool
        Settle the proof levels (:meth:`TransitionSystem.prove`), as ``build_abstraction`` does.

    Returns
    -------
    TransitionSystem
        ``stats``: ``radius``, ``n_edges``, ``n_lps`` (HiGHS solves at this radius),
        ``certified_non_edges`` (instances with ``upper < rho - tie_tol``), ``n_ties`` (HiGHS
        solves of instances whose ``lower`` is below ``rho + tie_tol``), ``verdicts``, ``provenance``,
        ``n_zero_margin``, ``n_unconfirmed``, ``rho_star_highs_solves``, ``seconds``, ...
    """

    t0 = time.perf_counter()
    rho = float(rho)
    if not (np.isfinite(rho) and rho >= 0):
        raise ValueError(f"the radius must be a finite number >= 0, got {rho}")
    if system is None:
        s = table.system
        system = dataclasses.replace(s, W=scaled_disturbance(table.W0, rho))     # every other part kept
    check_scaled_disturbance(system.W, table.W0, rho)
    r_file, factor = _file_units(system.W, table.W0, rho)
    L_max = table.L_max if L_max is None else int(L_max)
    idx, inv, first = table._pair_ids(L_max)             # sorted by (src, dst, L): runs per pair
    stop = np.append(first[1:], len(idx))
    certified = table.upper[idx] < rho - tie_tol
    likely = table.lower[idx] >= rho + tie_tol
    search = _first_edges(table, system, idx, (first, stop), certified, likely, workers)
    found, results, verdicts, provenance = search.found, search.results, search.verdicts, search.provenance
    pairs = np.flatnonzero(found >= 0)
    src, dst = table.src[idx[first[pairs]]], table.dst[idx[first[pairs]]]
    n_refine = table.refine((src, dst), L_max, workers)
    crit = table.critical(L_max)
    edges, tubes = [], []
    for p in pairs:
        a = found[p]
        e = Edge.from_verdict(int(table.src[idx[a]]), int(table.dst[idx[a]]), int(table.L[idx[a]]), results[p])
        edges.append(dataclasses.replace(e, rho_star=max(float(crit.value[p]) * factor, r_file)))
        tubes.append(results[p].tube)
    stats = {
        "n_cells": table.decomposition.n_cells, "n_edges": len(edges), "n_lps": search.n_solves,
        "radius": rho, "L_max": L_max, "method": table.form, "from_radius_table": True,
        "certified_non_edges": int(certified.sum()), "n_ties": int(search.n_ties),
        "verdicts": dict(verdicts), "provenance": dict(provenance),
        "n_zero_margin": int(sum(abs(e.margin) <= ZERO_MARGIN_TOL for e in edges)),
        "n_unconfirmed": int(verdicts.get("unconfirmed", 0)),
        "rho_star_highs_solves": int(n_refine), "rho_star_exact": int(np.sum(crit.exact[pairs])),
    }
    ts = TransitionSystem(table.decomposition, system, table.Z, edges, tubes, table.eps_min, table.form, stats)
    if prove:
        ts.prove()
    stats["seconds"] = time.perf_counter() - t0
    return ts


class _Search(NamedTuple):
    """What :func:`_first_edges` found: per pair (``P``) the run position of its edge (``-1``: none) and
    its verdict, the verdicts and provenances counted, and the HiGHS solves (of them, ties)."""

    found: np.ndarray
    results: dict
    verdicts: Counter
    provenance: Counter
    n_solves: int
    n_ties: int


def _first_edges(table: RadiusTable, system: LinearSystem, idx: np.ndarray, runs: tuple, certified: np.ndarray,
                 likely: np.ndarray, workers) -> _Search:
    """Each pair's smallest ``L`` that is an edge at ``system``'s radius: HiGHS verdicts of the instances not
    ``certified`` non-edges, in rounds of one instance per pair, increasing ``L``.

    ``idx`` orders the table's instances by ``(src, dst, L)``; ``runs = (first, stop)`` bound each pair's
    run of positions in it; ``likely`` marks the instances whose lower bound is clear of the radius (a tie
    otherwise)."""
    first, stop = runs
    P = len(first)
    reference = table.stats.get("solver") == "highs"
    verdict = partial(highs_verdict, form=table.form)
    base = formulation(table.form).provenance
    pos = first.copy()                                   # next run position of each pair
    found = np.full(P, -1)                               # run position of the pair's edge
    verdicts, provenance = Counter(), Counter()
    results: dict = {}
    n_ties = n_solves = 0
    while True:
        jobs = []                                        # (pair, run position)
        for p in np.flatnonzero((found < 0) & (pos < stop)):
            a = pos[p]
            while a < stop[p] and certified[a]:
                a += 1
            if a < stop[p]:
                jobs.append((p, a))
            pos[p] = a + 1
        if not jobs:
            break
        ks = idx[[a for _, a in jobs]]
        names = [base if reference else ("pdhg+highs" if likely[a] and table.provenance[idx[a]] == "pdhg"
                                         else "highs-fallback") for _, a in jobs]
        out = highs_map(verdict, list(zip(table.problems(ks, system), names)), workers)
        n_solves += len(jobs)
        n_ties += sum(not likely[a] for _, a in jobs)
        for (p, a), v in zip(jobs, out):
            verdicts[v.status] += 1
            provenance[v.provenance] += 1
            if v.status == "edge":
                found[p] = a
                results[p] = v
    return _Search(found, results, verdicts, provenance, n_solves, n_ties)


def n_edges_vs_L_max(ts: TransitionSystem, L_max: int | None = None) -> np.ndarray:
    """Edges of ``ts`` restricted to ``L <= L'`` for ``L' = 1 .. L_max``, shape ``(L_max,)``: the
    system at every smaller ``L_max`` (a pair's cost does not depend on ``L_max``)."""
    L_max = int(ts.stats.get("L_max", max([e.L for e in ts.edges], default=1))) if L_max is None else int(L_max)
    counts = np.bincount([e.L for e in ts.edges], minlength=L_max + 1)[1:L_max + 1]
    return np.cumsum(counts)
