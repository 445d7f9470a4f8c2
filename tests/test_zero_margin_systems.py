"""A map full of zero-margin transitions: every solver path gives the same, exact system.

On an open 2 x 7 grid with the paper's system (``A = I``, ``B = 0.5 I``, box ``U``, ball ``W``
of radius 0.2, box ``Z``), every move of three columns has minimal horizon ``L = 10`` with
margin exactly 0 (``tests/lp/test_exact_decision.py`` derives it by hand and checks the
hand-built tube with the independent exact checker): ``L >= 10`` because the tube's trailing
face advances at most ``0.5 - 0.2 = 0.3`` per step. Such an edge used to be decided by the sign
of HiGHS's rounding error. Here HiGHS is perturbed -- primal instead of dual simplex, another
pricing, its reported margins shifted by ``+-1e-12`` --, every instance solved cold on its own
(the test's own walk of Algorithm 2, no translation classes), the batched solver, chunked rounds and
a resumed run are used: the edge
list (pairs and ``L``) and the provenances stay identical, and every three-column move is an
edge at exactly ``L = 10``.
"""

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction, cross_sections
from tubejax.model.geometry import Ball
from tubejax.lp.engines import highs
from tubejax.abstraction.runstore import RunStore
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import parse_grid_map

from one_by_one import assert_each_instance_on_its_own

COLS = 7
MAP = "\n".join(["." * COLS] * 2)


class Crash(Exception):
    pass


@pytest.fixture(scope="module")
def problem():
    return (parse_grid_map(MAP),
            LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2)))


def edges(ts):
    return [(e.src, e.dst, e.L) for e in ts.edges]


@pytest.fixture(scope="module")
def reference(problem):
    return build_abstraction(*problem, L_max=10, progress=False)


def test_every_three_column_move_is_an_edge_at_exactly_ten(problem, reference):
    d = problem[0]
    grid = d.grid
    by_pair = {(e.src, e.dst): e for e in reference.edges}
    moves = [(i, j) for i in range(d.n_cells) for j in range(d.n_cells)
             if abs(int(grid[i][1]) - int(grid[j][1])) == 3]
    assert len(moves) == 2 * 2 * 2 * (COLS - 3)              # rows x rows x directions x starts
    for i, j in moves:
        e = by_pair[i, j]
        assert e.L == 10 and e.proof == "exact" and 0 <= e.margin <= 1e-9, (i, j, e)
    assert reference.stats["n_decided_exactly"]["primal proof"] >= len(moves)
    # every refused instance that reached a solver kept its evidence
    ne = reference.nonedges
    assert len(ne) == reference.stats["n_lps"] - reference.n_edges
    assert set(ne.counts()) <= {"dual", "exact", "translate", "bounds"}


@pytest.fixture
def fresh_highs():
    """HiGHS objects made anew (the thread's cached one carries the options it was made with)."""
    if hasattr(highs._local, "highs"):
        del highs._local.highs
    yield
    if hasattr(highs._local, "highs"):
        del highs._local.highs


def shifted(monkeypatch, delta):
    orig = highs._result

    def noisy(*a, **kw):
        r = orig(*a, **kw)
        return r._replace(margin=r.margin + delta) if r.status == "Optimal" else r

    monkeypatch.setattr(highs, "_result", noisy)


def test_every_instance_solved_on_its_own_gives_the_identical_system(problem, reference):
    d, s = problem
    assert_each_instance_on_its_own(reference, d, s, cross_sections(d, "box", 1.0), 10)


@pytest.mark.parametrize("variant", ["primal simplex", "dantzig pricing", "margins +1e-12", "margins -1e-12",
                                     "small memory budget"])
def test_highs_perturbations_give_the_identical_system(problem, reference, monkeypatch, fresh_highs, variant):
    kw = {}
    if variant == "primal simplex":
        monkeypatch.setitem(highs.HIGHS_OPTIONS, "simplex_strategy", 4)
    elif variant == "dantzig pricing":
        monkeypatch.setitem(highs.HIGHS_OPTIONS, "simplex_dual_edge_weight_strategy", 0)
    elif variant.startswith("margins"):
        shifted(monkeypatch, 1e-12 if "+" in variant else -1e-12)
    else:
        kw["memory_budget_mb"] = 1
    ts = build_abstraction(*problem, L_max=10, progress=False, **kw)
    assert edges(ts) == edges(reference)
    assert [e.provenance for e in ts.edges] == [e.provenance for e in reference.edges]


def test_the_batched_solver_with_shifted_margins_gives_the_identical_system(problem, reference, monkeypatch,
                                                                             fresh_highs):
    from tubejax.lp.batch.batch_solver import PdhgBatchSolver
    shifted(monkeypatch, -1e-12)
    solver = PdhgBatchSolver(pool=32, min_bucket=32, l_buckets=(10,), tail_width=None, highs_process=False)
    ts = build_abstraction(*problem, L_max=10, progress=False, solve_batch=solver)
    assert edges(ts) == edges(reference)


def test_a_resumed_run_gives_the_identical_system(tmp_path, problem, reference):
    seen = []

    def crash(L, e, t):
        seen.append(L)
        if len(seen) == 4:
            raise Crash

    store = RunStore(tmp_path)
    store.create({"run": "test"})
    with pytest.raises(Crash):
        build_abstraction(*problem, L_max=10, progress=False, store=store, on_round=crash)
    ts = build_abstraction(*problem, L_max=10, progress=False, store=RunStore(tmp_path))
    assert edges(ts) == edges(reference)
    assert [e.provenance for e in ts.edges] == [e.provenance for e in reference.edges]
    assert ts.nonedges.index().keys() == reference.nonedges.index().keys()
    assert [r.kind for r in ts.nonedges.refutations] == [r.kind for r in reference.nonedges.refutations]
    assert ts.stats["n_decided_exactly"] == reference.stats["n_decided_exactly"]      # the resumed steps' too
