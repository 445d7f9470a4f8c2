"""Issue 24: a progress bar over the runs of a simulation (10,000 runs printed nothing for ~50 s); checking
the runs in chunks changes no result."""

import jax

jax.config.update("jax_enable_x64", True)

import dataclasses  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.analyses.control import SimulationRuns, plan_sequence, simulate  # noqa: E402
from tubejax.analyses.control.simulate import CHUNK_RUNS  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace.gridmap import load_grid_map  # noqa: E402


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    m = tmp_path_factory.mktemp("map") / "small.txt"
    m.write_text("1.4.2\n.###.\n3....\n")
    d = load_grid_map(m)
    ts = build_abstraction(d, LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2)),
                           L_max=10, progress=False)
    return ts, plan_sequence(ts, d.cells_with_label("1")[0], ["2", "3"])


class Recorder:
    """A tqdm-like object that records its updates."""

    def __init__(self):
        self.updates = []

    def update(self, k):
        self.updates.append(k)


def same_result(a, b) -> bool:
    for f in dataclasses.fields(a):
        x, y = getattr(a, f.name), getattr(b, f.name)
        if isinstance(x, np.ndarray):
            if x.shape != y.shape or not np.array_equal(x, y):
                return False
    return a.summary() == b.summary()


@pytest.mark.parametrize("mode", ["uniform", "adversarial"])
def test_chunks_advance_the_bar_and_change_nothing(small, mode):
    ts, plan = small
    whole = simulate(ts, plan, SimulationRuns(n_runs=250, mode=mode, seed=3))
    rec = Recorder()
    chunked = simulate(ts, plan, SimulationRuns(n_runs=250, mode=mode, seed=3, chunk_runs=64), progress=rec)
    assert rec.updates == [64, 64, 64, 58]                   # one update per chunk, summing to the runs
    assert same_result(whole, chunked)                       # bit for bit, every array and the summary
    assert CHUNK_RUNS >= 250 and whole.n_runs == 250


def test_progress_bar_has_the_runs_as_total(small, capsys):
    ts, plan = small
    simulate(ts, plan, SimulationRuns(n_runs=300, mode="uniform", seed=0, chunk_runs=100), progress=True)
    err = capsys.readouterr().err
    assert "simulating (uniform)" in err and "0/300" in err   # the total is known from the start
    simulate(ts, plan, SimulationRuns(n_runs=300, mode="uniform", seed=0))
    assert capsys.readouterr().err == ""                      # progress=False (the default): silent


def test_bad_chunk_size(small):
    ts, plan = small
    for bad in (0, -1, 2.5, True):
        with pytest.raises(ValueError, match="chunk_runs"):
            simulate(ts, plan, SimulationRuns(n_runs=10, chunk_runs=bad))
