"""The dense builder and the float64 checker of :mod:`.dense`, for many problems at once.

The translates of one tube problem (:mod:`tubejax.translations`) differ only in where their
sets lie: the LP matrix of :func:`~.dense.build_tube_lp` is the same for all of them, and
only the right-hand sides and the variable bounds move. :func:`build_tube_lps` builds the
matrix once and each problem's right-hand side and bounds with the same arithmetic, so each
LP equals :func:`~.dense.build_tube_lp`'s bit for bit (a test holds them to it).
:func:`tube_violations` evaluates :func:`~.dense.tube_violation` for many tubes in one pass.
Problems that do not share the matrix are built and checked one by one.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ....geometry import support
from .dense import (TubeLP, build_tube_lp, tube_hard_rows, tube_rhs, tube_rows, tube_variable_bounds_batch,
                    tube_violation)

__all__ = ["build_tube_lps", "tube_violations", "same_tube_rows"]


def same_tube_rows(a, b) -> bool:
    """Whether two tube problems have the same LP matrix (see :func:`~.dense.tube_rows`)."""
    if a is b:
        return True
    return (int(a.L) == int(b.L) and a.system is b.system and a.source.n_vertices == b.source.n_vertices
            and (a.Z is b.Z or (np.array_equal(a.Z.vertices, b.Z.vertices) and np.array_equal(a.Z.H, b.Z.H)
                                and np.array_equal(a.Z.h, b.Z.h)))
            and np.array_equal(a.safe.H, b.safe.H) and np.array_equal(a.target.H, b.target.H))


def build_tube_lps(problems: Sequence, t_max: float = 1.0) -> list:
    """:func:`~.dense.build_tube_lp` of each of ``problems``.

    The problems whose matrix equals the first one's share one read-only ``G`` (and
    ``G_hard``); their bounds come from one :func:`~.dense.tube_variable_bounds_batch` call.

    Returns
    -------
    list of TubeLP, length K
    """
    if not problems:
        return []
    p0 = problems[0]
    same = [k for k, p in enumerate(problems) if same_tube_rows(p0, p)]
    out: list = [None] * len(problems)
    G, kinds, rows = tube_rows(p0)
    nrm = np.linalg.norm(G, axis=1)
    G /= nrm[:, None]
    G.setflags(write=False)
    G_hard, g_hard = tube_hard_rows(p0)
    G_hard.setflags(write=False)
    lb, ub = tube_variable_bounds_batch([problems[k] for k in same])
    for a, k in enumerate(same):
        g = tube_rhs(problems[k], rows)
        g /= nrm
        out[k] = TubeLP(G, g, kinds, G_hard, g_hard.copy(), lb[a], ub[a], float(t_max), rows.index)
    for k, p in enumerate(problems):
        if out[k] is None:
            out[k] = build_tube_lp(p, t_max)
    return out


def tube_violations(problems: Sequence, tubes: Sequence) -> np.ndarray:
    """:func:`~.dense.tube_violation` of ``tubes[k]`` for ``problems[k]``, shape ``(K,)``.

    Problems that share ``L``, the system, ``Z``, ``eps_min`` and the facet normals of ``S``
    and ``P_j`` with the first one are checked in one pass (the same rows, in the same
    order); the others one by one.
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
    from ..zshape import source_points
    ks = [k for k, _ in batch]
    p, eps, u = (np.array([parts[a] for _, parts in batch]) for a in range(3))   # (B, L, n) (B, L) (B, L, nv, m)
    q = p[:, :, None, :] + eps[:, :, None, None] * p0.Z.vertices[None, None, :, :]    # (B, L, nv, n)
    q0 = np.array([source_points(problems[k].source, nv).vertices for k in ks])       # (B, nv, n)
    worst = [np.max(p0.eps_min - eps, axis=1)]                                        # C1
    if L > 1:                                                                         # C2
        hs = np.array([problems[k].safe.h for k in ks])
        worst.append(np.max(q[:, :L - 1] @ p0.safe.H.T - hs[:, None, None, :], axis=(1, 2, 3)))
    ht = np.array([problems[k].target.h for k in ks])
    worst.append(np.max(q[:, L - 1] @ p0.target.H.T - ht[:, None, :], axis=(1, 2)))   # C3
    zn = np.linalg.norm(p0.Z.H, axis=1)
    Hz, hz = p0.Z.H / zn[:, None], p0.Z.h / zn
    sig_w = support(sysm.W, Hz)
    qall = np.concatenate([q0[:, None], q[:, :L - 1]], axis=1)                       # q_k(0..L-1)
    nxt = qall @ sysm.A.T + u @ sysm.B.T - p[:, :, None, :]
    worst.append(np.max(nxt @ Hz.T - eps[:, :, None, None] * hz + sig_w, axis=(1, 2, 3)))   # C4
    worst.append(np.max(u @ sysm.U.H.T - sysm.U.h, axis=(1, 2, 3)))                          # C5
    v = np.maximum(0.0, np.max(np.stack(worst), axis=0))
    finite = np.all(np.isfinite(p), axis=(1, 2)) & np.all(np.isfinite(eps), axis=1) & np.all(np.isfinite(u), axis=(1, 2, 3))
    out[ks] = np.where(finite, v, np.inf)
    return out
