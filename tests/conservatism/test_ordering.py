"""The learned Z inside the limit, and the inclusions between the methods that are theorems.

Which inclusions of ``open loop ⊆ tube ⊆ exact2d ⊆ limit`` hold for every problem
(docs/math/limit.md#which-inclusions-are-theorems):

* **tube ⊆ exact2d, edge by edge** (any ``Z``, a learned one included): a feasible tube LP for
  ``(i, j, L)`` is one causal feedback (the interpolating controller of Lemma 1) that keeps every
  state of ``P_i`` in the pair's safe set ``S`` at steps ``1 … L−1`` and puts it in ``P_j`` at step
  ``L``; ``exact2d`` decides, by dynamic programming over the same ``S``, ``P_j`` and ``L``, whether
  *some* causal feedback does, and rounds in the permissive direction. So every tube edge is an
  exact2d edge, at a horizon no shorter than exact2d's least one.
* **open loop ⊆ exact2d, edge by edge**: the same argument — inputs fixed at time 0 are a
  (degenerate) causal feedback, with the same ``S`` and ``P_j``.
* **exact2d ⊆ limit, cell by cell** (Theorem 4): a path of edges chains the edges' feedbacks
  into one that reaches ``T`` inside ``S``.

Winning sets are monotone in the edge set, so the first two give ``winning(tube)`` and
``winning(open loop)`` ``⊆ winning(exact2d)``.

**open loop ⊆ tube is not a theorem.** The tube's sets are scaled translates of one ``Z`` with each
vertex of ``Z`` tied to one vertex of the cell; the open loop moves each vertex of the cell by its
own input sequence (the nominal set may shear or rotate) and covers the accumulated disturbance
``D_ℓ`` exactly rather than by a scaled ``Z``. Neither search space contains the other, and
:func:`test_the_open_loop_is_not_inside_the_tube_in_general` exhibits open-loop edges that the
tube with a diamond ``Z`` does not certify, and shorter open-loop horizons even with a box ``Z``.
So it is not tested as an inclusion.

The learned ``Z`` is learned here by the library's path (:func:`tubejax.analyses.zshape.learn_z`
from a thin rectangle, which the fixed kinds are not, then
:func:`~tubejax.analyses.zshape.table_from_learned` and ``zshape='learned'``), on the small maps of
``test_winning.py``, in seconds.
"""

import functools

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.analyses.conservatism import cells_outside, reach_avoid_limit, winning_set
from tubejax.analyses.zshape import LearnOptions, learn_z, table_from_learned, use_z_table
from tubejax.reachability.exact2d import exact_edges
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace.gridmap import parse_grid_map

CORRIDOR = "1..#...\n.#.#.#.\n.#...#2\n...#...\n"
AVOID_MAP = "1.4.2\n.###.\n3....\n"
#: (map, target, avoid, A), as in test_winning.py: the limit is smaller than S for the last two.
CASES = {
    "avoid": (AVOID_MAP, "2", ("4",), np.eye(2)),
    "shear": (CORRIDOR, "2", (), np.array([[1.0, 0.3], [0.0, 1.0]])),
    "saddle": (CORRIDOR, "2", (), np.array([[1.1, 0.0], [0.0, 0.9]])),
}
L_MAX = 6
THIN = Polytope.box([-1.0, -0.25], [1.0, 0.25])                # not a fixed kind: learning must move it


def _system(A, r):
    return LinearSystem(A=A, B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, r))


@functools.lru_cache(maxsize=None)
def _problem(case, r):
    text, target, avoid, A = CASES[case]
    decomp = parse_grid_map(text)
    system = _system(A, r)
    return decomp, system, reach_avoid_limit(decomp, system, target, avoid)


@functools.lru_cache(maxsize=None)
def _learned(case, r):
    """The tube abstraction with a Z learned from the thin rectangle, and the learned Z's vertices."""
    decomp, system, _ = _problem(case, r)
    res = learn_z(decomp, system, init=lambda i, j: THIN,
                  options=LearnOptions(steps=4, learning_rate=0.1, L_max=L_MAX), progress=False)
    with use_z_table(table_from_learned(res, decomp)):
        ts = build_abstraction(decomp, system, zshape="learned", L_max=L_MAX, progress=False)
    return ts, res


@functools.lru_cache(maxsize=None)
def _run(case, r, method, zshape="box"):
    decomp, system, _ = _problem(case, r)
    return build_abstraction(decomp, system, method=method, zshape=zshape, L_max=L_MAX, progress=False)


def _least_exact(case, r):
    decomp, system, _ = _problem(case, r)
    return {pair: L for pair, (L, *_rest) in exact_edges(decomp, system, L_MAX).items()}


def _not_exact(ts, exact) -> list:
    """The edges of ``ts`` that are no exact2d edge, or shorter than exact2d's least horizon."""
    return [(e.src, e.dst, e.L) for e in ts.edges
            if (e.src, e.dst) not in exact or e.L < exact[(e.src, e.dst)]]


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("r", [0.1, 0.2])
def test_the_learned_z_wins_only_inside_the_limit(case, r):
    _, target, avoid, _ = CASES[case]
    decomp, _, lim = _problem(case, r)
    assert lim.converged
    ts, res = _learned(case, r)
    assert ts.stats["zshape"] == "learned" and ts.n_edges > 0
    assert not np.allclose(res.z[0], res.start_z[0]), "learning left the thin start where it was"
    assert np.all(ts.verify() <= 1e-9)
    win = winning_set(ts, target, avoid)
    bad = cells_outside(win, lim.geometry, decomp)
    assert not bad, (f"{case}, r = {r}, tube (learned Z): winning cells partly outside the limit "
                     + ", ".join(f"cell {c} ({a:.3g} of its area)" for c, a in bad))
    assert win.area <= lim.area * (1 + 1e-9)


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("r", [0.1, 0.2])
def test_tube_and_open_loop_edges_are_exact2d_edges(case, r):
    exact = _least_exact(case, r)
    runs = {f"tube ({z} Z)": _run(case, r, "tube", z) for z in ("box", "diamond", "cell")}
    runs["tube (learned Z)"] = _learned(case, r)[0]
    runs["openloop"] = _run(case, r, "openloop")
    ex_ts = _run(case, r, "exact2d")
    assert {(e.src, e.dst): e.L for e in ex_ts.edges} == exact        # the app's exact2d is exact_edges
    for name, ts in runs.items():
        bad = _not_exact(ts, exact)
        assert not bad, f"{case}, r = {r}, {name}: edges (src, dst, L) beyond exact2d: {bad}"


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("r", [0.1, 0.2])
def test_winning_sets_nest_tube_and_open_loop_in_exact2d_in_the_limit(case, r):
    _, target, avoid, _ = CASES[case]
    decomp, _, lim = _problem(case, r)
    exact = winning_set(_run(case, r, "exact2d"), target, avoid)
    assert not cells_outside(exact, lim.geometry, decomp), f"{case}, r = {r}: exact2d wins outside the limit"
    for name, ts in [("tube (box Z)", _run(case, r, "tube")), ("tube (learned Z)", _learned(case, r)[0]),
                     ("openloop", _run(case, r, "openloop"))]:
        extra = sorted(set(winning_set(ts, target, avoid).cells) - set(exact.cells))
        assert not extra, f"{case}, r = {r}: {name} wins cells {extra} that exact2d does not"


def test_the_open_loop_is_not_inside_the_tube_in_general():
    """Why ``open loop ⊆ tube`` is not tested as an inclusion: counterexamples on the corridor."""
    shear = {(e.src, e.dst) for e in _run("shear", 0.15, "openloop").edges}
    diamond = {(e.src, e.dst) for e in _run("shear", 0.15, "tube", "diamond").edges}
    assert shear - diamond, "every open-loop edge is a tube (diamond Z) edge here after all"
    decomp = parse_grid_map(CORRIDOR)
    rot = _system(np.array([[0.9, -0.3], [0.3, 0.9]]), 0.05)
    ol = {(e.src, e.dst): e.L for e in build_abstraction(decomp, rot, method="openloop", L_max=5,
                                                         progress=False).edges}
    box = {(e.src, e.dst): e.L for e in build_abstraction(decomp, rot, zshape="box", L_max=5,
                                                          progress=False).edges}
    assert any(p in box and L < box[p] for p, L in ol.items()), "no open-loop edge is shorter than the tube's"
