"""The optimiser step of :func:`~tubejax.analyses.zshape.learn.learn_z` and the loop that runs it.

:func:`make_step` jits one Adam step on the surrogate with a backtracking acceptance per group;
:func:`optimise` runs it, keeping each group's best iterate, and stops groups by ``patience`` or
``require_gain`` (docs/howto/learned-z.md#the-objective-and-the-step).
"""

from __future__ import annotations

import logging
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from tqdm.auto import tqdm

from ...model.zshape.params import ZFamily, repair_theta, theta_mask, z_from_theta, z_valid
from .margin import PairMargins
from .starts import CERTIFIED_TOL, better, group_scores, phi, soft_count

__all__ = ["Classes", "make_step", "optimise"]

log = logging.getLogger("tubejax")

#: The step runs a few dozen times per learning run: XLA's faster compile beats faster code
#: (docs/explanation/performance.md#learning-z).
_XLA_OPTIONS = {"xla_cpu_use_fusion_emitters": False}


def make_step(pm: PairMargins, family: ZFamily, opt, tau: float, t0: float, group_of_pair, weight,
               max_halvings: int):
    """The jitted optimiser step ``(theta, state, L) -> (theta', state', F, t, moved)``; ``F`` counts
    instance ``b`` ``weight[b]`` times (the size of its translation class)."""
    gop = jnp.asarray(group_of_pair)
    w = jnp.asarray(weight, dtype=jnp.float64)
    mask = jnp.asarray(theta_mask(family))
    fractions = jnp.asarray(0.5 ** np.arange(max_halvings + 1))
    zs = jax.vmap(lambda th: z_from_theta(family, th))
    valid = jax.vmap(lambda z: z_valid(family, z))
    norm_theta = jax.vmap(lambda th: repair_theta(family, th))

    def objective(theta, L):
        t = pm(zs(theta)[gop], L)
        return jnp.sum(w * phi(t, tau, t0)), t

    @partial(jax.jit, compiler_options=_XLA_OPTIONS)
    def step(theta, state, L):
        (obj, t), grad = jax.value_and_grad(objective, has_aux=True)(theta, L)
        updates, state = opt.update(-grad * mask, state, theta)
        updates = updates * mask
        # the first valid of the full, half, quarter, ... step, per group (all candidates at once)
        cand = jax.vmap(lambda f: norm_theta(theta + f * updates))(fractions)      # (H, G, ...)
        ok = jax.vmap(valid)(jax.vmap(zs)(cand))                                    # (H, G)
        first = jnp.argmax(ok, axis=0)
        moved = jnp.any(ok, axis=0)
        pick = jnp.take_along_axis(cand, first[None, :, None, None], axis=0)[0]
        new = jnp.where(moved[:, None, None], pick, theta)
        return new, state, obj, t, moved

    return step


class Classes(NamedTuple):
    """The translation classes that :func:`~tubejax.analyses.zshape.learn.learn_z` solves, one pair each."""

    group: np.ndarray      # (C,) int: the group whose Z the class uses
    size: np.ndarray       # (C,) int: the pairs it stands for


def optimise(run, opt, theta0, classes: Classes, tau: float, options, what: str, progress: bool):
    """Run the steps of :func:`~tubejax.analyses.zshape.learn.learn_z` from ``theta0`` (one row per group),
    keeping each group's best iterate.

    ``run(theta, state) -> (theta, state, objective, t (C,), accepted (G,))`` is one step of the optax ``opt``;
    ``options`` is the run's :class:`~tubejax.analyses.zshape.learn.LearnOptions` (``steps``, ``target``,
    ``patience``, ``require_gain``).

    Returns
    -------
    best : ndarray
        Each group's best parameters (its start where ``require_gain`` saw no strict gain).
    best_t, start_t : ndarray (B,)
        The margins of the classes' representatives at the best iterate and at the start.
    history : list of dict
        Per step: ``step``, ``objective``, ``certified``, ``accepted``.
    """
    gop, size = classes
    theta = jnp.asarray(theta0)
    state = opt.init(theta)
    G = len(theta0)
    best = np.asarray(theta0).copy()
    best_score = np.full((G, 2), -np.inf)
    start_t = best_t = None
    history = []
    last_gain = np.zeros(G, dtype=int)
    n_of_group = np.bincount(gop, weights=size, minlength=G)
    stopped = np.zeros(G, dtype=bool)
    bar = tqdm(range(options.steps + 1), desc=what, disable=not progress, leave=False)
    for k in bar:
        new_theta, new_state, obj, t, ok = run(theta, state)
        t = np.asarray(t)
        score = group_scores(t, soft_count(t, tau, options.target * tau), gop, G, size)
        if start_t is None:
            start_t = best_t = t.copy()
            start_score = score.copy()
        won = better(score, best_score)
        if np.any(won):
            last_gain[won] = k
            best[won] = np.asarray(theta)[won]
            best_score[won] = score[won]
            best_t = np.where(won[gop], t, best_t)
        rec = {"step": k, "objective": float(obj), "certified": int(np.sum(size * (t >= -CERTIFIED_TOL))),
               "accepted": int(np.sum(np.asarray(ok) & ~stopped))}
        history.append(rec)
        # a group stops once its best has not improved for `patience` steps, or (require_gain) when its
        # start certifies all its pairs; it then stays put, so its LPs are not solved again
        if options.patience is not None:
            stopped |= k - last_gain >= options.patience
        if options.require_gain:
            stopped |= start_score[:, 0] >= n_of_group
        bar.set_postfix(objective=f"{rec['objective']:.2f}", certified=rec["certified"],
                        best=int(np.sum(best_score[:, 0])), active=int(G - stopped.sum()))
        log.info("%s step %d: objective %.4f, pairs certified at their L %d, groups moved %d, "
                 "groups still learning %d", what, k, rec["objective"], rec["certified"], rec["accepted"],
                 int(G - stopped.sum()))
        if np.all(stopped):
            log.info("%s: every group has stopped (no gain in %s steps, or nothing to gain), at step %d",
                     what, options.patience, k)
            break
        if k < options.steps:
            theta = jnp.where(jnp.asarray(stopped).reshape((G,) + (1,) * (theta.ndim - 1)), theta, new_theta)
            state = new_state
    bar.close()
    if options.require_gain:
        keep = best_score[:, 0] <= start_score[:, 0]              # no strict gain: the start stays
        best[keep] = np.asarray(theta0)[keep]
        best_t = np.where(keep[gop], start_t, best_t)
    return best, best_t, start_t, history
