"""Typed settings all the way down (issue 44, items 2 and 3): the engine's three settings records, its
immutable statistics, the status enumeration, Algorithm 2's options, and the retired ``reuse_duals``
key (old records load, configs that set it are refused by name)."""

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest

import tubejax as tj
from tubejax.abstraction import AbstractionOptions, build_abstraction
from tubejax.abstraction.methods import batch_solver
from tubejax.errors import InputError, InputModelError
from tubejax.inputs import ProblemInputs
from tubejax.lp.evidence.verdict import highs_solve_batch
from tubejax.lp.batch.batch_solver import Executor, PdhgBatchSolver, PoolOptions, SolverStats
from tubejax.lp.engines.engine_options import split_options
from tubejax.lp.engines.pdhg import STATUS_NAMES, PdhgOptions, PdhgStatus
from tubejax.model.workspace import parse_grid_map

TINY = Path(__file__).resolve().parent / "data" / "tiny.txt"


def base() -> dict:
    return {
        "workspace": {"kind": "grid", "map_file": str(TINY)},
        "system": {"name": "integrator2d", "A": [[1.0, 0.0], [0.0, 1.0]], "B": [[0.5, 0.0], [0.0, 0.5]],
                   "U": {"kind": "box", "bound": 1.0}},
        "disturbance": {"kind": "ball", "radius": 0.2},
        "zshape": {"kind": "box", "scale": 1.0},
        "abstraction": {"L_max": 10, "method": "tube", "solver": {"name": "pdhg", "pool": 64, "dtype": "float64"}},
    }


def test_flat_options_are_sorted_into_the_three_records_and_an_unknown_one_is_named():
    pdhg, pool, ex = split_options({"max_iters": 64, "pool": 32, "chunk": 8, "highs_process": False})
    assert (pdhg, pool, ex) == ({"max_iters": 64}, {"pool": 32, "chunk": 8}, {"highs_process": False})
    s = PdhgBatchSolver(PdhgOptions(check_every=8), PoolOptions(min_bucket=8), Executor(highs_process=False),
                        pool=16, max_iters=64)
    assert (s.options.check_every, s.options.max_iters) == (8, 64)
    assert (s.pooling.pool, s.pooling.min_bucket, s.executor.highs_process) == (16, 8, False)
    with pytest.raises(TypeError, match="unknown option 'reuse_duals'"):
        PdhgBatchSolver(reuse_duals=False)


def test_horizons_are_padded_to_auto_buckets_or_given_ones_and_another_mode_is_refused():
    auto = PdhgBatchSolver(highs_process=False)
    assert [auto.l_pad(L) for L in (1, 2, 3, 5, 8, 9, 13, 17, 25, 33)] == [2, 2, 4, 8, 8, 12, 16, 24, 32, 48]
    given = PdhgBatchSolver(l_buckets=[10, 4], highs_process=False)
    assert given.pooling.l_buckets == (4, 10)
    assert [given.l_pad(L) for L in (1, 4, 5, 10, 11)] == [4, 4, 10, 10, 11]
    for retired in ("pow2", "exact"):
        with pytest.raises(ValueError, match=f"l_buckets: expected 'auto' or a sequence of horizons, got '{retired}'"):
            PdhgBatchSolver(l_buckets=retired, highs_process=False)


def test_statistics_are_an_immutable_typed_snapshot():
    s = PdhgBatchSolver(highs_process=False)
    st = s.stats
    assert isinstance(st, SolverStats) and st.n_lps == st["n_lps"] == 0 and set(st) == set(dict(st))
    with pytest.raises(dataclasses.FrozenInstanceError):
        st.n_lps = 3
    with pytest.raises(TypeError):
        st.status_counts["feasible"] = 1
    with pytest.raises(TypeError):
        st["n_lps"] = 1                                 # not a mutable dict
    assert json.loads(json.dumps(dict(st)))["status_counts"] == {}          # what a run's stats file stores
    s.tally.add("n_lps", 5)
    assert st.n_lps == 0 and s.stats.n_lps == 5         # a snapshot does not move with the solver


def test_statuses_are_an_enumeration_whose_names_key_the_counts():
    assert [int(v) for v in PdhgStatus] == list(range(len(STATUS_NAMES)))
    assert STATUS_NAMES == tuple(v.name.lower() for v in PdhgStatus)
    assert STATUS_NAMES[PdhgStatus.NEAR_ZERO] == "near_zero"


def test_an_old_record_carrying_reuse_duals_loads_and_a_config_setting_it_is_refused_by_name():
    record = ProblemInputs.from_dict(base()).record()
    assert "reuse_duals" not in record["abstraction"]["solver"]
    old = {**record, "abstraction": {**record["abstraction"],
                                     "solver": {**record["abstraction"]["solver"], "reuse_duals": False}}}
    assert ProblemInputs.from_record(old).record() == record
    data = base()
    data["abstraction"]["solver"]["reuse_duals"] = True
    with pytest.raises(InputModelError) as info:
        ProblemInputs.from_dict(data)
    assert re.search(r"abstraction\.solver.*reuse_duals.*removed.*delete it", str(info.value), re.S)


def test_abstraction_options_and_fields_by_name_build_the_same_system():
    d = parse_grid_map("##########\n#1..#...2#\n#...#....#\n#........#\n##########")
    s = tj.paper_system(0.2)
    opt = AbstractionOptions(L_max=4, zshape="box")
    a = build_abstraction(d, s, opt, solve_batch=highs_solve_batch, progress=False)
    b = build_abstraction(d, s, solve_batch=highs_solve_batch, progress=False, L_max=4, zshape="box")
    assert a.n_edges > 0 and [(e.src, e.dst, e.L) for e in a.edges] == [(e.src, e.dst, e.L) for e in b.edges]
    with pytest.raises(ValueError, match="L_max"):
        AbstractionOptions(L_max=0)
    with pytest.raises(ValueError, match="exact2d has no margin"):
        opt.replace(method="exact2d", min_margin=0.1)


def test_the_api_names_an_unknown_argument():
    with pytest.raises(InputError, match=r"^reuse_duals: not an argument of tubejax.abstract"):
        tj.abstract("#####\n#1.2#\n#####", tj.paper_system(0.2), reuse_duals=False)


def test_the_factory_gives_the_engine_its_typed_settings():
    inputs = ProblemInputs.from_dict(base())
    solver = batch_solver(inputs.abstraction)
    assert solver.pooling == PoolOptions(pool=64, dtype="float64")
    assert solver.executor == Executor() and solver.options == PdhgOptions()
    assert np.isnan(solver.stats.iterations_median)
