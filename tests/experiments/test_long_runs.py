"""Issue 21 (resources): long runs show an estimate, work that cannot fit is refused up front, and
the bookkeeping of a run stays linear in its size.

Speed itself is measured in scripts (README), not here: these tests check the mechanisms.
"""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tubejax.abstraction import pruning
from tubejax.abstraction.candidates import build_candidates
from tubejax.model.geometry import Ball
from tubejax.abstraction.pruning import prune_pairs, reach_tables
from tubejax.abstraction.schedule import PairSchedule, horizon_cost
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import load_grid_map

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / "tests" / "data" / "tiny.txt"


def _brute_remaining(s: PairSchedule):
    cols = np.arange(1, s.L_max + 1)
    left = s.keep[s.edge_L == 0] & (cols[None, :] >= s.next_L[s.edge_L == 0, None])
    return int(left.sum()), float((left * s.cost[None, :]).sum())


def test_schedule_counts_what_is_left_incrementally_and_exactly():
    rng = np.random.default_rng(0)
    keep = rng.random((60, 25)) < 0.4
    s = PairSchedule(keep)
    assert (s.remaining(), s.remaining_cost()) == _brute_remaining(s)
    while (L := s.min_open()) is not None:
        ks = s.open_at(L)
        edge = rng.random(len(ks)) < 0.15
        s.settle(ks, L, edge)
        n, cost = _brute_remaining(s)
        assert s.remaining() == n and s.remaining_cost() == pytest.approx(cost, rel=1e-12, abs=1e-9)
    assert s.remaining() == 0 and s.remaining_cost() == pytest.approx(0.0, abs=1e-9)


def test_estimate_weights_instances_by_their_horizon():
    keep = np.zeros((2, 100), dtype=bool)
    keep[:, :] = True
    s = PairSchedule(keep)
    assert s.seconds_left(10.0) is None and "instances left" in s.progress(10.0)
    s.settle(np.array([0, 1]), 1, False)                      # two cheap LPs in 1 s
    eta = s.seconds_left(1.0)
    left = 2 * sum(horizon_cost(L) for L in range(2, 101))
    assert eta == pytest.approx(left / (2 * horizon_cost(1)))
    assert eta > 5 * (198 / 2)               # counting LPs (198 left, 2 done in 1 s) would say 99 s
    assert s.progress(1.0).endswith(" at the current pace")


def test_estimate_follows_a_run_that_slows_down():
    keep = np.ones((1, 400), dtype=bool)
    s = PairSchedule(keep)
    t = 0.0
    for L in range(1, 201):                              # the model's pace for 200 rounds ...
        t += 1e-3 * horizon_cost(L)
        s.settle(np.array([0]), L, False)
        s.seconds_left(t)
    steady = s.seconds_left(t)
    assert steady == pytest.approx(1e-3 * sum(horizon_cost(L) for L in range(201, 401)), rel=1e-6)
    for L in range(201, 221):                            # ... then 10 x slower for a while
        t += 1e-2 * horizon_cost(L)
        s.settle(np.array([0]), L, False)
        s.seconds_left(t)
    assert s.seconds_left(t) > 5 * steady * (180 / 200)


def test_pruning_in_small_chunks_gives_the_same_result(monkeypatch):
    d = load_grid_map(ROOT / "conf" / "workspace" / "maps" / "paper.txt")
    system = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    T = reach_tables(d, system, 40)
    src = np.repeat(np.arange(d.n_cells), 3)
    dst = (src + np.tile([1, 2, 5], d.n_cells)) % d.n_cells
    ref = prune_pairs(d, system, T, src, dst)
    monkeypatch.setattr(pruning, "PRUNE_CHUNK_ELEMENTS", 40 * T.cell.shape[2] * 7)    # 7 pairs at a time
    small = prune_pairs(d, system, T, src, dst)
    assert np.array_equal(ref[0], small[0]) and np.array_equal(ref[1], small[1]) and ref[2] == small[2]
    c = build_candidates(d, system, 40)
    assert c.keep.shape[1] == 40 and c.n_instances > 0


def test_memory_budget_too_small_for_one_lp_at_l_max_is_refused_up_front(tmp_path):
    p = subprocess.run([sys.executable, str(ROOT / "experiments" / "abstract.py"), "progress=false",
                        f"workspace.map_file={TINY}", "solver=highs", "L_max=1000", "memory_budget_mb=1", "budget.max_lp_size=null",
                        f"hydra.run.dir={tmp_path / 'run'}"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p.returncode == 2 and "Traceback" not in p.stderr, p.stderr[-2000:]
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("error: ")]
    assert len(lines) == 1 and lines[0].startswith(
        "error: memory_budget_mb: one LP at horizon L_max = 1000 needs about 14 MB"), p.stderr[-2000:]
    assert "raise memory_budget_mb to at least 14, or lower L_max" in lines[0]
    assert not (tmp_path / "run" / "rounds").exists()


def test_round_log_lines_carry_an_estimate(tmp_path):
    p = subprocess.run([sys.executable, str(ROOT / "experiments" / "abstract.py"), "progress=false",
                        f"workspace.map_file={TINY}", "solver=highs", "L_max=12",
                        f"hydra.run.dir={tmp_path / 'run'}"], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    rounds = [ln for ln in (tmp_path / "run" / "abstract.log").read_text().splitlines() if "] - L=" in ln]
    assert rounds and all("at most " in ln and " instances left" in ln for ln in rounds), rounds[:3]
    assert any(", at most ~" in ln and ln.endswith(" at the current pace") for ln in rounds), rounds[:3]
