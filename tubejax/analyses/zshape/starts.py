"""The start of learning ``Z`` and the scores that compare iterates (:func:`tubejax.analyses.zshape.learn.learn_z`).

A score per group is (pairs certified, surrogate), each pair weighted by its translation class's size;
with several ``init``, :func:`starts` takes per group the best start and its horizons (:func:`horizons`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import jax
import numpy as np
from scipy.special import expit

from ...model.zshape.kinds import make_z
from .margin import PairMargins
from ...model.zshape.params import normalise_theta_host, theta_from_z, z_from_theta_host, z_valid_host

if TYPE_CHECKING:
    from .learn import LearnOptions

__all__ = ["CERTIFIED_TOL", "StartGroups", "phi", "soft_count", "better", "group_scores", "start_z", "start_theta",
           "starts", "horizons"]

#: A margin at or above ``-CERTIFIED_TOL`` counts as certified while learning (zero-margin edges are
#: edges; the abstraction decides them exactly afterwards).
CERTIFIED_TOL = 1e-9


class StartGroups(NamedTuple):
    """The ``G`` groups learned together and the ``C`` instances (translation classes) they solve."""

    cells: np.ndarray      # (G,) int: a source cell of each group (where its start is made)
    targets: list          # (G,) int or None: the group's target cell (``learned_pair``), None for a shared Z
    of_pair: np.ndarray    # (C,) int: each instance's group
    weight: np.ndarray     # (C,) int: the pairs each instance stands for (its translation class's size)


def phi(t, tau, t0):
    """The soft count ``sigmoid((t - t0) / tau)`` of margins ``t`` (any shape)."""
    return jax.nn.sigmoid((t - t0) / tau)


def soft_count(t, tau, t0) -> np.ndarray:
    """:func:`phi` on the host (numpy, float64), same shape as ``t``."""
    return expit((np.asarray(t, dtype=np.float64) - t0) / tau)


def better(a, b):
    """Groups where score ``a`` beats ``b`` (more certified pairs, then a larger surrogate), ``(G,)``."""
    return (a[:, 0] > b[:, 0]) | ((a[:, 0] == b[:, 0]) & (a[:, 1] > b[:, 1]))


def group_scores(t, soft, group_of_pair, G, weight=None):
    """Per group: (pairs with ``t >= 0``, surrogate), shape ``(G, 2)``.

    ``t``, ``soft`` (:func:`phi` of ``t``) and ``group_of_pair`` have shape ``(B,)``; ``weight (B,)``
    counts each of the ``B`` instances that many times (the size of its translation class; default 1).
    """
    w = np.ones(len(t)) if weight is None else np.asarray(weight, dtype=float)
    out = np.zeros((G, 2))
    np.add.at(out[:, 0], group_of_pair, w * (t >= -CERTIFIED_TOL))
    np.add.at(out[:, 1], group_of_pair, w * soft)
    return out


def horizons(pm: PairMargins, keep, z, how: str, need_t: bool = True):
    """``(L_p (B,), t_p (B,) or None)`` for the candidates of ``pm`` with cross-sections ``z (B, n_v, n)``:
    ``'last'`` the largest unpruned ``L``, ``'best'`` the ``L`` of largest margin (one LP per
    unpruned ``(pair, L)``)."""
    Ls = [np.flatnonzero(keep[i, j]) + 1 for i, j in pm.pairs]
    last = np.array([int(l[-1]) for l in Ls])
    if how == "last":
        return last, (pm.solve(z, last).t if need_t else None)
    best, top = last.copy(), np.full(len(Ls), -np.inf)
    for L in range(1, pm.L_max + 1):
        sel = np.array([L in l for l in Ls])
        if not sel.any():
            continue
        idx = np.flatnonzero(sel)
        t = pm.solve_subset(z, np.full(len(Ls), L), idx)
        upd = t > top[idx]
        best[idx[upd]], top[idx[upd]] = L, t[upd]
    return best, top


def start_z(init, decomp, i: int, j):
    """The starting ``Z`` of source cell ``i`` (pair ``(i, j)``, ``j = None`` for a shared ``Z``)."""
    if callable(init):
        return init(i, j)
    if init == "target":
        if j is None:
            raise ValueError("init 'target' (Z shaped like the target cell) needs mode 'learned_pair'")
        return make_z("cell", decomp.cells[j])
    return make_z(init, decomp.cells[i])


def start_theta(family, init, decomp, groups: StartGroups, rng, jitter: float):
    """Parameters of the starting ``Z`` of each group for one ``init`` (see :func:`learn_z`)."""
    out = []
    for i, j in zip(groups.cells, groups.targets):
        Z = start_z(init, decomp, int(i), None if j is None else int(j))
        th = np.asarray(normalise_theta_host(family, theta_from_z(family, Z)))
        if jitter > 0:
            for _ in range(20):
                cand = th + jitter * rng.standard_normal(th.shape)
                if z_valid_host(family, z_from_theta_host(family, cand)):
                    th = cand
                    break
        out.append(th)
    return np.stack(out)


def starts(pm: PairMargins, inits, groups: StartGroups, keep, options: LearnOptions, rng, tau: float):
    """The start of each group, the horizon of each pair and the ``init`` chosen per group:
    ``(theta (G, ...), L (B,), index (G,))``.

    Every ``init`` gives its horizons (:func:`horizons`, ``options.horizon``; the start moved by
    ``options.jitter`` drawn from ``rng``); with several, each group takes the ``init`` whose ``Z``
    certifies most of its pairs at those horizons (then the largest surrogate of temperature ``tau``
    and target ``options.target * tau``; pairs weighted as in :func:`group_scores`), with its horizons.
    """
    family, t0 = pm.family, options.target * tau
    G = len(groups.cells)
    best = best_L = None
    score = np.full((G, 2), -np.inf)
    index = np.zeros(G, dtype=int)
    for n_init, init in enumerate(inits):
        th = start_theta(family, init, pm.decomp, groups, rng, options.jitter)
        z = np.stack([np.asarray(z_from_theta_host(family, t)) for t in th])[groups.of_pair]
        L, t = horizons(pm, keep, z, options.horizon, need_t=len(inits) > 1)
        if len(inits) == 1:
            return th, L, index
        sc = group_scores(t, soft_count(t, tau, t0), groups.of_pair, G, groups.weight)
        won = better(sc, score)
        best = th if best is None else np.where(won.reshape((G,) + (1,) * (th.ndim - 1)), th, best)
        best_L = L if best_L is None else np.where(won[groups.of_pair], L, best_L)
        score = np.where(won[:, None], sc, score)
        index = np.where(won, n_init, index)
    return best, best_L, index
