"""The dense builder and the float64 checker of :mod:`.tube_lp`, for many problems at once.

Translates of one tube problem share the LP matrix; only right-hand sides and bounds move.
:func:`build_tube_lps` builds the matrix once and the rest per problem with the same arithmetic, so
each LP equals :func:`~.tube_lp.build_tube_lp`'s bit for bit (a test holds them to it);
:func:`tube_violations` checks many tubes in one pass. Others are built one by one.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from .tube_lp import (TubeLP, build_tube_lp, margin_csr, margin_rows, row_kinds, tube_hard_rows, tube_violation,
                      worst_residual)
from .tube_variables import tube_index, tube_variable_bounds_batch
from .tube_families import TUBE_FAMILIES, TubeVars, float_terms, region_sets, tube_residuals
from .row_families import dense_rhs

__all__ = ["build_tube_lps", "tube_violations", "same_tube_rows"]


def same_tube_rows(a, b) -> bool:
    """Whether two tube problems have the same LP matrix: the rows of
    :data:`~.tube_families.TUBE_FAMILIES` depend on ``L``, the system, ``Z``, the source's vertex
    count and the facet normals of ``S`` and ``P_j`` only (not on where the sets lie)."""
    if a is b:
        return True
    return (int(a.L) == int(b.L) and a.system is b.system and a.source.n_vertices == b.source.n_vertices
            and (a.Z is b.Z or (np.array_equal(a.Z.vertices, b.Z.vertices) and np.array_equal(a.Z.H, b.Z.H)
                                and np.array_equal(a.Z.h, b.Z.h)))
            and np.array_equal(a.safe.H, b.safe.H) and np.array_equal(a.target.H, b.target.H))


def _translated_terms(problems, ks):
    """:func:`~.tube_families.float_terms` of ``problems[ks]`` (sharing rows with ``problems[ks[0]]``),
    with their sources' vertices and the offsets of ``S`` and ``P_j`` on a leading batch axis."""
    p0 = problems[ks[0]]
    h = {r: np.array([region_sets(problems[k])[r].h for k in ks]) for r in ("safe", "target")}
    return float_terms(p0, V=np.array([problems[k].source.vertices for k in ks]), h=h)


def build_tube_lps(problems: Sequence, t_max: float = 1.0, scaling: str = "state") -> list:
    """:func:`~.tube_lp.build_tube_lp` of each of ``problems``; those whose matrix equals the first's share
    one read-only ``G`` (and ``G_hard``), with batched right-hand sides and bounds.

    Returns
    -------
    list of TubeLP, length K
    """
    if not problems:
        return []
    p0 = problems[0]
    same = [k for k, p in enumerate(problems) if same_tube_rows(p0, p)]
    out: list = [None] * len(problems)
    G, _, nrm, layout = margin_rows(p0, scaling=scaling, rhs=False)
    G_hard, g_hard = tube_hard_rows(p0)
    G_hard.setflags(write=False)
    lp0 = TubeLP(G, None, row_kinds(layout), G_hard, g_hard, None, None, float(t_max), tube_index(p0), layout=layout,
                 G_csr=margin_csr(p0, scaling=scaling, rhs=False)[0])
    g = dense_rhs(_translated_terms(problems, same), "margin", p0.system.u_is_box, TUBE_FAMILIES) / nrm
    lb, ub = tube_variable_bounds_batch([problems[k] for k in same])
    for a, k in enumerate(same):
        out[k] = lp0._replace(g=g[a], g_hard=lp0.g_hard.copy(), lb=lb[a], ub=ub[a])
    for k, p in enumerate(problems):
        if out[k] is None:
            out[k] = build_tube_lp(p, t_max, scaling)
    return out


def tube_violations(problems: Sequence, tubes: Sequence) -> np.ndarray:
    """:func:`~.tube_lp.tube_violation` of ``tubes[k]`` for ``problems[k]``, shape ``(K,)``.

    Problems that share ``L``, the system, ``Z``, ``eps_min`` and the facet normals of ``S``
    and ``P_j`` with the first one are checked in one pass (the same residuals with a batch
    axis); the others one by one.
    """
    K = len(problems)
    out = np.full(K, np.nan)
    if K == 0:
        return out
    p0 = problems[0]
    sysm = p0.system
    L, n, nv, m = int(p0.L), sysm.n, p0.source.n_vertices, sysm.m
    batch = []
    for k, (p, t) in enumerate(zip(problems, tubes)):
        parts = [np.asarray(a, float) for a in t]
        if (same_tube_rows(p0, p) and p.eps_min == p0.eps_min and parts[0].shape == (L, n)
                and parts[1].shape == (L,) and parts[2].shape == (L, nv, m)):
            batch.append((k, parts))
        else:
            out[k] = tube_violation(p, t)
    if not batch:
        return out
    ks = [k for k, _ in batch]
    x = TubeVars(*(np.array([parts[a] for _, parts in batch]) for a in range(3)))
    v = np.maximum(0.0, worst_residual(tube_residuals(_translated_terms(problems, ks), x), (len(ks),)))
    finite = (np.all(np.isfinite(x.p), axis=(1, 2)) & np.all(np.isfinite(x.eps), axis=1)
              & np.all(np.isfinite(x.u), axis=(1, 2, 3)))
    out[ks] = np.where(finite, v, np.inf)
    return out
