"""``min_margin``: an edge needs a robustness margin ``t* >= min_margin`` (issue 11, "exact proofs").

Checked against an independent computation: HiGHS's optimal margin ``t*(i, j, L)`` of every
candidate, from which the least ``L`` with ``t* >= m`` is read off directly.
"""

import jax

jax.config.update("jax_enable_x64", True)

import json  # noqa: E402
import math  # noqa: E402
import shutil  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.errors import InputModelError  # noqa: E402
from tubejax.inputs import ProblemInputs  # noqa: E402
from tubejax.lp.evidence.verdict import evidence_margin, highs_solve_batch  # noqa: E402
from tubejax.lp.declarations.tube_lp import build_tube_lp  # noqa: E402
from tubejax.lp.engines.highs import solve_margin_lp  # noqa: E402
from tubejax.model.problem import pair_problem  # noqa: E402
from tubejax.transitions.transition_system import TransitionSystem  # noqa: E402
from tubejax.verify.verifier import verify_directory  # noqa: E402

MAP = "1...\n.#..\n...2\n"
L_MAX = 6
# between the margins 0.04 and 0.05 that pairs of this map have (state-space distances): some pairs
# lose their transition, others keep it at a longer horizon
M = 0.045


def _inputs(map_path, min_margin=M, method="tube"):
    return ProblemInputs.from_dict({
        "workspace": {"kind": "grid", "map_file": str(map_path)},
        "system": {"A": [[1.0, 0.0], [0.0, 1.0]], "B": [[0.5, 0.0], [0.0, 0.5]], "U": {"kind": "box", "bound": 1.0}},
        "disturbance": {"kind": "ball", "radius": 0.1},
        "abstraction": {"L_max": L_MAX, "min_margin": min_margin, "method": method, "solver": {"name": "highs"}},
    })


@pytest.fixture(scope="module")
def problem(tmp_path_factory):
    d = tmp_path_factory.mktemp("mm")
    (d / "map.txt").write_text(MAP)
    inputs = _inputs(d / "map.txt")
    return d, inputs, inputs.build_decomposition(), inputs.build_system()


@pytest.fixture(scope="module")
def margins(problem):
    """HiGHS's optimal margin of every ordered pair and horizon, ``{(i, j): [t*(1) .. t*(L_MAX)]}``."""
    _, inputs, decomp, system = problem
    Z = build_abstraction(decomp, system, L_max=1, progress=False).Z
    out = {}
    for i in range(decomp.n_cells):
        for j in range(decomp.n_cells):
            if i != j:
                out[i, j] = [solve_margin_lp(build_tube_lp(pair_problem(decomp, system, Z[i], i, j, L))).margin
                             for L in range(1, L_MAX + 1)]
    return out


@pytest.fixture(scope="module")
def saved(problem):
    d, inputs, decomp, system = problem
    ts = build_abstraction(decomp, system, **inputs.abstraction_kwargs(), solve_batch=highs_solve_batch,
                           progress=False)
    ts.inputs = inputs.record()
    ts.save(d / "run")
    return d, ts


def _expected(margins, m):
    out = set()
    for (i, j), ts in margins.items():
        L = next((L for L, t in enumerate(ts, 1) if t >= m), None)
        if L is not None:
            out.add((i, j, L))
    return out


def test_edges_are_the_least_horizons_with_the_margin(problem, margins, saved):
    _, ts = saved
    # the test's threshold is not a near-tie (HiGHS's 1e-9 could decide either way there)
    assert min(abs(t - M) for v in margins.values() for t in v) > 1e-6
    got = {(e.src, e.dst, e.L) for e in ts.edges}
    assert got == _expected(margins, M)
    plain = _expected(margins, 0.0)
    L0 = {(i, j): L for i, j, L in plain}
    assert {(i, j) for i, j, _ in got} < set(L0)      # strictly fewer transitions, each no shorter
    assert all(L >= L0[i, j] for i, j, L in got)
    assert ts.min_margin == M and ts.stats["min_margin"] == M
    for k, e in enumerate(ts.edges):
        assert e.margin >= M
        assert evidence_margin(build_tube_lp(ts.problem(k)), ts.tubes[k]) >= M - 1e-9
    assert np.all(ts.verify() <= 1e-9)


def test_pdhg_gives_the_same_system(problem, saved):
    from tubejax.lp.batch.batch_solver import PdhgBatchSolver
    _, inputs, decomp, system = problem
    _, ts = saved
    solver = PdhgBatchSolver(pool=32, min_bucket=8, highs_process=False)
    got = build_abstraction(decomp, system, **inputs.abstraction_kwargs(), solve_batch=solver, progress=False)
    assert [(e.src, e.dst, e.L) for e in got.edges] == [(e.src, e.dst, e.L) for e in ts.edges]


def test_files_keep_it_and_verify_checks_it(saved, tmp_path):
    d, ts = saved
    back = TransitionSystem.load(d / "run")
    assert back.min_margin == M
    assert verify_directory(d / "run", progress=False).ok
    out = tmp_path / "run"
    shutil.copytree(d / "run", out)
    doc = json.loads((out / "transitions.json").read_text())
    doc["min_margin"] = 0.0                                   # the copy no longer says what was demanded
    (out / "transitions.json").write_text(json.dumps(doc))
    rep = verify_directory(out, progress=False)
    assert not rep.ok and any("min_margin: the file says 0.0" in f for f in rep.findings)
    doc["min_margin"] = 0.2                                   # demanded more than the edges have
    doc["inputs"]["abstraction"]["min_margin"] = 0.2
    (out / "transitions.json").write_text(json.dumps(doc))
    rep = verify_directory(out, progress=False)
    assert not rep.ok and any("below the required min_margin 0.2" in f for f in rep.findings)


@pytest.mark.parametrize("bad", [-0.1, 0.6, math.nan, math.inf, "big", True])
def test_bad_min_margin_refused(bad, tmp_path):
    (tmp_path / "map.txt").write_text(MAP)
    with pytest.raises(InputModelError, match="min_margin"):
        _inputs(tmp_path / "map.txt", min_margin=bad)


def test_exact2d_has_no_margin(tmp_path, problem):
    (tmp_path / "map.txt").write_text(MAP)
    with pytest.raises(InputModelError, match="min_margin.*exact2d"):
        _inputs(tmp_path / "map.txt", method="exact2d")
    _, _, decomp, system = problem
    with pytest.raises(ValueError, match="exact2d has no margin"):
        build_abstraction(decomp, system, method="exact2d", min_margin=0.1, progress=False)
    with pytest.raises(ValueError, match="min_margin must be"):
        build_abstraction(decomp, system, min_margin=1.5, progress=False)
