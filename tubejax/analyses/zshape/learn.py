"""Learning ``Z`` with optax: maximise a smooth surrogate of the number of certified transitions
(the surrogate, the modes, the translates and the step: docs/howto/learned-z.md#the-objective-and-the-step).

Each group (a cell shape, or a pair) keeps its own best iterate, so learning never ends below its
start. Deterministic: HiGHS runs single-threaded with a fixed seed, and the only randomness, an
optional jitter of the start, comes from ``seed``.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
import optax

from ...abstraction.candidates import build_candidates
from .margin import PairMargins
from ...model.zshape.params import ZFamily, family_for, final_z, polytope_from_z
from ...model.zshape.kinds import z_vertex_count_problem
from ...model.zshape.z_table import cell_shape_key
from ...abstraction.translation_classes import pair_classes
from .starts import StartGroups, start_z, starts
from .step import Classes, make_step, optimise

__all__ = ["LearnOptions", "LearnedZ", "learn_z", "candidate_pairs"]

MODES = ("learned", "learned_pair")


class LearnOptions(NamedTuple):
    """Settings of :func:`learn_z`.

    Attributes
    ----------
    steps : int               optimiser steps (each solves every candidate's LP once)
    learning_rate : float     Adam step size (parameters are vertices of RMS radius ``sqrt(n)``)
    temperature : float       ``τ`` of the sigmoid, in units of the cell size
    target : float            ``t_0 / τ``: a pair counts fully once ``t_p`` is this many ``τ`` above 0
    horizon : {'last', 'best'}
    max_halvings : int        backtracking halvings before a group's step is rejected
    jitter : float            standard deviation of a seeded perturbation of the start (0: none)
    seed : int
    patience : int or None    a group stops (stays put, its LPs no longer solved) once its best
                              iterate has not improved for this many steps; learning ends when
                              every group has stopped (``None``: run all ``steps``)
    require_gain : bool       a group keeps its start unless its best iterate certifies strictly
                              more of its pairs at their ``L`` (a tie on that count with a larger
                              surrogate may lose an edge the start has at another horizon); then
                              learning stops at once when the start certifies every pair
    L_max, eps_min, pruning   the candidate pairs and their margin LPs, as the run's
                              :func:`~tubejax.abstraction.build_abstraction`; with ``pruning``, one pair
                              is solved per translation class (also keyed by the unpruned horizons and
                              the group or start ``Z``), counted once per pair of its class: exact
                              translates have the same margin
    """

    steps: int = 30
    learning_rate: float = 0.03
    temperature: float = 0.02
    target: float = 0.5
    horizon: str = "last"
    max_halvings: int = 4
    jitter: float = 0.0
    seed: int = 0
    patience: int | None = None
    require_gain: bool = False
    L_max: int = 10
    eps_min: float = 0.0
    pruning: bool = True


class LearnedZ(NamedTuple):
    """What :func:`learn_z` returns (``G`` groups, ``B`` candidate pairs).

    Attributes
    ----------
    mode : str
    family : ZFamily
    pairs : (B, 2) int         candidate pairs ``(i, j)``
    L : (B,) int               their horizons
    group_of_pair : (B,) int
    group_cells : (G,) int     a source cell of each group (its shape defines the group)
    z : (G, n_v, n)            the best ``Z`` of each group (normalised vertices, canonical order)
    start_z : (G, n_v, n)
    margins : (B,)             ``t_p`` at ``z``
    start_margins : (B,)
    history : list of dict     per step: ``step``, ``objective``, ``certified`` (pairs with
                               ``t_p >= 0`` at their ``L``), ``accepted`` (groups that moved)
    seconds : float
    n_lps : int                margin LPs solved
    n_compiles : int           compilations of the optimiser step (1: no recompiles)
    start_index : (G,) int     which ``init`` of the sequence each group started from (0 for one)
    n_classes : int            translation classes, the instances solved per step (``B`` without)
    """

    mode: str
    family: ZFamily
    pairs: np.ndarray
    L: np.ndarray
    group_of_pair: np.ndarray
    group_cells: np.ndarray
    z: np.ndarray
    start_z: np.ndarray
    margins: np.ndarray
    start_margins: np.ndarray
    history: list
    seconds: float
    n_lps: int
    n_compiles: int = 1
    start_index: np.ndarray | None = None
    n_classes: int | None = None

    def polytopes(self) -> list:
        """The checked :class:`Polytope` of each group (:func:`~tubejax.model.zshape.params.polytope_from_z`)."""
        return [polytope_from_z(self.family, z) for z in self.z]


def cell_size(decomp) -> float:
    """Median over cells of the smallest bounding-box width (the unit of margins here)."""
    return float(np.median([np.min(np.subtract(*c.bounding_box()[::-1])) for c in decomp.cells]))


def candidate_pairs(decomp, system, L_max: int, pruning: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Pairs with some unpruned horizon and that mask: ``(pairs (B, 2), keep (N, N, L_max))``."""
    N = decomp.n_cells
    cand = build_candidates(decomp, system, L_max, pruning=pruning)
    keep = np.zeros((N, N, L_max), dtype=bool)      # dense: the learner is meant for maps of modest size
    keep[cand.src, cand.dst] = cand.keep
    return np.argwhere(keep.any(axis=2)), keep


def learn_z(decomp, system, *, mode: str = "learned", init="box", options: LearnOptions = LearnOptions(),
            progress: bool = True, pairs=None, n_vertices: int | None = None) -> LearnedZ:
    """Learn ``Z`` for the candidate pairs of ``decomp`` (see the module docstring).

    Parameters
    ----------
    decomp : CellDecomposition
        Every source cell of a candidate must have the same vertex count (one family).
    system : LinearSystem
    mode : {'learned', 'learned_pair'}
    init : str, callable or sequence of them
        The start: a fixed kind (:func:`~tubejax.model.zshape.kinds.make_z`), ``'target'``
        (``learned_pair`` only: the target cell's shape, ``make_z('cell', P_j)``), or
        ``init(i, j) -> Polytope`` for source cell ``i`` (``j``: the pair's target, ``None`` for
        a shared ``Z``); several: per group the one whose ``Z`` certifies most pairs at their
        ``L`` (then the largest surrogate).
    options : LearnOptions
        The optimiser, and the candidates and LPs (``L_max``, ``eps_min``, ``pruning``).
    pairs : array of int (B, 2), optional
        Restrict the candidates to these pairs (each must survive the pruning).
    n_vertices : int, optional
        2-D: learn ``Z`` with this many vertices, a multiple of the source cells' (``2 n_i``:
        the ``chamfer`` family, paired with :func:`~tubejax.model.zshape.kinds.source_points`);
        default: the cells' own count.

    Returns
    -------
    LearnedZ

    Raises
    ------
    ValueError
        Unknown mode or option, no candidate, or source cells with different vertex counts.
    """
    t_start = time.perf_counter()
    _check_options(mode, options)
    L_max, eps_min = options.L_max, options.eps_min
    cand, keep = _learned_pairs(decomp, system, L_max, options.pruning, pairs)
    family = _learned_family(decomp, cand, n_vertices)
    inits = list(init) if isinstance(init, (list, tuple)) else [init]
    if not inits:
        raise ValueError("init: expected a kind, a callable or a non-empty sequence of them")
    if mode == "learned":
        group_of_pair, group_cells = _shape_groups(decomp, cand)
        own = group_of_pair[:, None]
    else:
        own = _start_ids(inits, decomp, cand)
    first, of, size = _pair_classes(decomp, system, cand, keep, own, bool(options.pruning))
    reps = cand[first]
    if mode == "learned":
        group_cells, gop = np.array(group_cells), group_of_pair[first]
        group_targets = [None] * len(group_cells)
    else:
        group_cells, gop = reps[:, 0].copy(), np.arange(len(reps))
        group_targets = [int(j) for j in reps[:, 1]]
    tau = options.temperature * cell_size(decomp)
    pm = PairMargins(decomp, system, reps, family, L_max, eps_min)
    theta0, L, start_index = starts(pm, inits, StartGroups(group_cells, group_targets, gop, size), keep, options,
                                    np.random.default_rng(options.seed), tau)
    opt = optax.adam(options.learning_rate)
    step = make_step(pm, family, opt, tau, options.target * tau, gop, size, options.max_halvings)
    Lj = jnp.asarray(L)
    best, best_t, start_t, history = optimise(lambda theta, state: step(theta, state, Lj), opt, theta0,
                                               Classes(gop, size), tau, options, f"learning Z ({mode})", progress)
    z_best = np.stack([final_z(family, th) for th in best])
    z_start = np.stack([final_z(family, th) for th in theta0])
    group_of_pair = group_of_pair if mode == "learned" else of
    return LearnedZ(mode, family, cand, L[of], group_of_pair, group_cells, z_best, z_start, best_t[of], start_t[of],
                    history, time.perf_counter() - t_start, pm.solver.n_solves, int(step._cache_size()),
                    start_index, len(reps))


def _learned_pairs(decomp, system, L_max: int, pruning: bool, pairs) -> tuple[np.ndarray, np.ndarray]:
    """:func:`candidate_pairs`, restricted to ``pairs`` ``(B, 2)`` when given; none left is an error."""
    cand, keep = candidate_pairs(decomp, system, L_max, pruning)
    if pairs is not None:
        want = {tuple(map(int, p)) for p in np.asarray(pairs, dtype=int).reshape(-1, 2)}
        cand = np.array([p for p in cand if tuple(p) in want], dtype=int).reshape(-1, 2)
    if len(cand) == 0:
        raise ValueError("no candidate pair to learn Z for (everything is pruned)")
    return cand, keep


def _pair_classes(decomp, system, cand: np.ndarray, keep: np.ndarray, own, by_class: bool):
    """One instance per translation class: translates share ``Z`` (their start ``own``), ``L``, margin and
    gradient. Returns ``(first, of, size)`` of :func:`~tubejax.abstraction.translation_classes.pair_classes`
    (each pair its own class without ``by_class``)."""
    ints = np.column_stack([keep[cand[:, 0], cand[:, 1]].astype(np.int64)] + ([own] if own is not None else []))
    if by_class:
        return pair_classes(decomp, system, cand[:, 0], cand[:, 1], ints)
    return np.arange(len(cand)), np.arange(len(cand)), np.ones(len(cand), dtype=np.int64)


def _check_options(mode: str, options: LearnOptions) -> None:
    """Refuse an unknown ``mode`` or an option out of range (:func:`learn_z`)."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if options.horizon not in ("last", "best"):
        raise ValueError(f"options.horizon must be 'last' or 'best', got {options.horizon!r}")
    if options.steps < 0 or options.learning_rate <= 0 or options.temperature <= 0:
        raise ValueError(f"options need steps >= 0, learning_rate > 0, temperature > 0, got {options}")
    if options.patience is not None and options.patience < 1:
        raise ValueError(f"options.patience must be None or >= 1, got {options.patience}")


def _learned_family(decomp, cand: np.ndarray, n_vertices: int | None) -> ZFamily:
    """The one ``Z`` family of the source cells of ``cand`` ``(B, 2)``, with ``n_vertices`` vertices if given."""
    families = {family_for(decomp.cells[i]) for i, _ in cand}
    if len(families) != 1:
        raise ValueError(f"the source cells need one Z family, got {sorted(families)}: learn each "
                         "vertex count separately (pairs=...)")
    family = families.pop()
    if n_vertices is not None and int(n_vertices) != family.n_vertices:
        why = z_vertex_count_problem(int(n_vertices), family.n_vertices, family.n)
        if why is not None:
            raise ValueError(f"n_vertices: {why}")
        family = ZFamily("polygon", 2, int(n_vertices), int(n_vertices))
    return family


def _shape_groups(decomp, cand: np.ndarray) -> tuple[np.ndarray, list]:
    """``learned``: the groups of source cells of one shape (equal up to translation).

    Returns
    -------
    group_of_pair : ndarray of int (B,)
        Each pair's group, numbered in order of first appearance.
    group_cells : list of int (G,)
        Each group's first source cell.
    """
    keys, group_of_pair, group_cells = {}, [], []
    for i, _ in cand:
        k = cell_shape_key(decomp.cells[i].vertices)
        if k not in keys:
            keys[k] = len(group_cells)
            group_cells.append(int(i))
        group_of_pair.append(keys[k])
    return np.array(group_of_pair), group_cells


def _start_ids(inits, decomp, cand):
    """For ``learned_pair``: per pair, an id of its starting ``Z`` under each callable ``init``
    (``(B, c)``, equal ids for equal vertices), or ``None`` when every ``init`` is a kind (the
    start then depends on the cells' shapes only, which the translation key holds)."""
    calls = [f for f in inits if callable(f)]
    if not calls:
        return None
    ids: dict = {}
    return np.array([[ids.setdefault(np.ascontiguousarray(start_z(f, decomp, int(i), int(j)).vertices,
                                                          dtype=float).tobytes(), len(ids)) for f in calls]
                     for i, j in cand], dtype=np.int64)
