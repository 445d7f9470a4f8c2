"""Resumable, memory-bounded, sharded runs of Algorithm 2 (issue 10, items 4 and 5), in the library.

An interruption is simulated by an exception at a chosen point (after a committed step, or
inside a solver call with confirmations still waiting); the run is then resumed from the
round files with a fresh :class:`RunStore` and must give the identical transition system as
an uninterrupted run: edges, ``L``, margins, provenance, proof levels and the tubes bit for bit.
"""

from concurrent.futures import Future

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.lp.evidence.verdict import Pending, highs_solve_batch
from tubejax.abstraction.runstore import RunStore, RunStoreError, record_differences, run_state
from tubejax.abstraction.schedule import MemoryBudget, PairSchedule
from tubejax.abstraction.shards import select_shard, shard_owner
from tubejax.model.workspace import load_grid_map


class Crash(Exception):
    pass


@pytest.fixture(scope="module")
def problem(corridor_path, paper_system):
    return load_grid_map(corridor_path), paper_system(0.2)


@pytest.fixture(scope="module")
def reference(problem):
    return build_abstraction(*problem, L_max=8, progress=False)


def assert_same_system(ts, ref):
    assert ts.edges == ref.edges                      # src, dst, L, margin, provenance, proof, violation
    assert len(ts.tubes) == len(ref.tubes)
    for a, b in zip(ts.tubes, ref.tubes):
        assert all(np.array_equal(x, y) for x, y in zip(a, b))
    for a, b in zip(ts.edges, ref.edges):
        assert (a.exact is None) == (b.exact is None)
        if a.exact is not None:
            assert all(np.array_equal(x.to_strings(), y.to_strings()) for x, y in zip(a.exact, b.exact))
    assert ts.stats["n_lps"] == ref.stats["n_lps"] and ts.stats["verdicts"] == ref.stats["verdicts"]


def crash_after(n_steps):
    seen = []

    def on_round(L, e, t):
        seen.append(L)
        if len(seen) == n_steps:
            raise Crash
    return on_round


@pytest.mark.parametrize("n_steps", [1, 7, 20])
def test_resume_after_a_crash_between_steps_gives_the_identical_system(tmp_path, problem, reference, n_steps):
    store = RunStore(tmp_path)
    store.create({"run": "test"})
    with pytest.raises(Crash):
        build_abstraction(*problem, L_max=8, progress=False, memory_budget_mb=1, store=store,
                          on_round=crash_after(n_steps))
    assert run_state(tmp_path) == "partial" and len(RunStore(tmp_path).manifest()["steps"]) == n_steps
    ts = build_abstraction(*problem, L_max=8, progress=False, memory_budget_mb=1, store=RunStore(tmp_path))
    assert 0 < ts.stats["resumed_lps"] < ts.stats["n_lps"]
    assert_same_system(ts, reference)
    # resuming a run whose every step is on disk solves nothing and gives it again
    again = build_abstraction(*problem, L_max=8, progress=False, store=RunStore(tmp_path))
    assert again.stats["resumed_lps"] == again.stats["n_lps"] and again.stats["rounds"] == []
    assert_same_system(again, reference)


class SlowConfirmations:
    """HiGHS verdicts, but every edge (and every 4th non-edge) comes back as a likely edge whose
    confirmation is done only ``delay`` solver calls later; call ``crash_at`` raises instead."""

    supports_deferred = True

    def __init__(self, delay=3, crash_at=None):
        self.delay, self.crash_at, self.calls = delay, crash_at, 0
        self.waiting: list = []
        self.solved: list = []

    def __call__(self, problems, progress=None, defer=False):
        self.calls += 1
        if self.calls == self.crash_at:
            raise Crash
        for item in self.waiting:
            item[0] -= 1
            if item[0] <= 0 and not item[1].done():
                item[1].set_result(item[2])
        self.solved += [(id(p.source), id(p.target), int(p.L)) for p in problems]
        out = []
        for k, v in enumerate(highs_solve_batch(problems)):
            if defer and (v.status == "edge" or k % 4 == 0):
                f = Future()
                self.waiting.append([self.delay, f, v])
                out.append(Pending(_Later(f, v), v.provenance))
            else:
                out.append(v)
        return out


class _Later:
    """A future that answers when asked (the helper finishing) or once its delay has passed."""

    def __init__(self, f, v):
        self.f, self.v = f, v

    def done(self):
        return self.f.done()

    def result(self):
        return self.v


@pytest.mark.parametrize("crash_at", [4, 9])
def test_resume_with_confirmations_still_waiting_gives_the_identical_system(tmp_path, problem, reference, crash_at):
    full = SlowConfirmations()
    ts_full = build_abstraction(*problem, L_max=8, progress=False, memory_budget_mb=1, solve_batch=full)
    assert_same_system(ts_full, reference)
    # each instance solved once (but those its translation class settled: tubejax.abstraction.translation_classes)
    assert len(full.solved) == len(set(full.solved)) == ts_full.stats["n_lps"] - ts_full.stats["n_translated"]
    store = RunStore(tmp_path)
    store.create({})
    crashing = SlowConfirmations(crash_at=crash_at)
    with pytest.raises(Crash):
        build_abstraction(*problem, L_max=8, progress=False, memory_budget_mb=1, solve_batch=crashing,
                          store=store)
    assert sum(not f.done() for _, f, _ in crashing.waiting) > 0       # confirmations were lost in the crash
    ts = build_abstraction(*problem, L_max=8, progress=False, memory_budget_mb=1,
                           solve_batch=SlowConfirmations(), store=RunStore(tmp_path))
    assert ts.stats["resumed_lps"] > 0
    assert_same_system(ts, reference)


def test_a_small_memory_budget_gives_the_same_result_in_more_chunks(problem, reference):
    small = build_abstraction(*problem, L_max=8, progress=False, memory_budget_mb=1)
    assert_same_system(small, reference)
    per_round = {}
    for r in small.stats["rounds"]:
        per_round[r["L"]] = per_round.get(r["L"], 0) + 1
    assert max(per_round.values()) > 1 and len(reference.stats["rounds"]) == len(per_round)
    budget = MemoryBudget(1, *problem, reference.Z)
    assert all(r["n_lps"] <= budget.chunk_size(r["L"]) for r in small.stats["rounds"])


def test_memory_budget_estimates():
    from tubejax.abstraction.schedule import lp_dimensions, padded_horizon

    assert [padded_horizon(L) for L in (1, 2, 3, 5, 8, 9, 10, 16)] == [2, 2, 4, 8, 8, 14, 15, 24]
    # docs/math/tube-lp.md for n = m = 2, a square source (4 vertices), box Z (4 facets): variables and rows
    assert lp_dimensions(2, 2, 4, 4, 6, 4, 3) == (3 * 3 + 3 * 8 + 1, 2 * 6 + 4 + 3 * 16)


def test_the_schedule_refuses_a_horizon_out_of_order():
    keep = np.array([[True, False, True, True], [False, True, False, False]])
    s = PairSchedule(keep)
    assert s.next_L.tolist() == [1, 2] and s.remaining() == 4
    with pytest.raises(ValueError, match="pair 0 settled at L=3, but its next horizon is 1"):
        s.settle([0], [3], [False])
    s.settle([0, 1], [1, 2], [False, False])
    assert s.next_L.tolist() == [3, 5] and s.min_open() == 3 and s.remaining() == 2
    s.suspend([0])
    assert s.min_open() is None and s.open_at(3).size == 0
    s.settle([0], [3], [True])
    assert s.edge_L.tolist() == [3, 0] and s.remaining() == 0
    with pytest.raises(ValueError, match="already has an edge at L=3"):
        s.settle([0], [3], [False])


def test_damaged_or_foreign_round_files_are_refused(tmp_path, problem):
    store = RunStore(tmp_path)
    store.create({})
    with pytest.raises(Crash):
        build_abstraction(*problem, L_max=8, progress=False, memory_budget_mb=1, store=store,
                          on_round=crash_after(3))
    (tmp_path / "rounds" / "00004-L04.npz.tmp").write_bytes(b"half a step")     # never committed
    with pytest.raises(RunStoreError, match="candidate instances differ.*L_max: 8 in the run, 6 now"):
        build_abstraction(*problem, L_max=6, progress=False, store=RunStore(tmp_path))
    step = sorted((tmp_path / "rounds").glob("00002-*.npz"))[0]
    step.write_bytes(step.read_bytes()[:-10])
    with pytest.raises(RunStoreError, match=f"{step.name}: its SHA-256 differs"):
        build_abstraction(*problem, L_max=8, progress=False, store=RunStore(tmp_path))
    assert not (tmp_path / "rounds" / "00004-L04.npz.tmp").exists()
    (tmp_path / "rounds" / "manifest.json").write_text("{")
    with pytest.raises(RunStoreError, match="manifest.json: cannot read the manifest"):
        RunStore(tmp_path).identity()


def test_record_differences_name_the_leaves():
    a = {"disturbance": {"radius": 0.2}, "workspace": {"map_file": {"sha256": "ab"}}, "x": [1, 2]}
    b = {"disturbance": {"radius": 0.1}, "workspace": {"map_file": {"sha256": "cd"}}, "x": [1, 3]}
    assert record_differences(a, b) == [("disturbance.radius", 0.2, 0.1), ("workspace.map_file.sha256", "ab", "cd"),
                                        ("x[1]", 2, 3)]
    assert record_differences(a, a) == []


def test_shards_partition_the_sources_and_together_give_the_unsharded_system(problem, reference):
    from tubejax.abstraction.candidates import build_candidates

    d, s = problem
    cand = build_candidates(d, s, 8)
    owner = shard_owner(cand.src, cand.keep, d.n_cells, 3)
    assert set(owner.tolist()) == {0, 1, 2} and np.all(np.diff(owner) >= 0)      # contiguous ranges
    load = [cand.keep[owner[cand.src] == k].sum() for k in range(3)]
    assert max(load) < 0.5 * sum(load)                                            # balanced by instances
    parts = [select_shard(cand, d.n_cells, 3, k) for k in range(3)]
    assert sum(len(p.src) for p in parts) == len(cand.src)
    edges = []
    for k in range(3):
        ts = build_abstraction(d, s, L_max=8, progress=False, shard=(3, k))
        assert ts.stats["shard"]["index"] == k and all(owner[e.src] == k for e in ts.edges)
        edges += ts.edges
    assert sorted(edges, key=lambda e: (e.src, e.dst)) == reference.edges


class TaggedSlowConfirmations(SlowConfirmations):
    """:class:`SlowConfirmations` whose likely edges carry their own provenance (``'slow+highs'``),
    as the batched solver's do, and that confirms a resumed run's waiting ones (``confirm_later``)."""

    def __call__(self, problems, progress=None, defer=False):
        out = super().__call__(problems, progress, defer)
        return [Pending(v.future, "slow+highs") if isinstance(v, Pending) else v for v in out]

    def confirm_later(self, problems, provenances):
        self.confirmed_later = len(problems)
        out = []
        for v, prov in zip(highs_solve_batch(problems), provenances):
            f = Future()
            f.set_result(v)
            out.append(Pending(f, prov))
        return out


@pytest.mark.parametrize("crash_at", [4, 9])
def test_a_resume_confirms_the_waiting_edges_with_their_provenance(tmp_path, problem, crash_at):
    full = build_abstraction(*problem, L_max=8, progress=False, memory_budget_mb=1,
                             solve_batch=TaggedSlowConfirmations())
    store = RunStore(tmp_path)
    store.create({})
    with pytest.raises(Crash):
        build_abstraction(*problem, L_max=8, progress=False, memory_budget_mb=1,
                          solve_batch=TaggedSlowConfirmations(crash_at=crash_at), store=store)
    again = TaggedSlowConfirmations()
    ts = build_abstraction(*problem, L_max=8, progress=False, memory_budget_mb=1, solve_batch=again,
                           store=RunStore(tmp_path))
    assert again.confirmed_later > 0                       # the step on disk listed them as waiting
    assert_same_system(ts, full)
    assert [e.provenance for e in ts.edges] == [e.provenance for e in full.edges]
    assert ts.stats["provenance"] == full.stats["provenance"]
