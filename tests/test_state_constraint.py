"""The state constraint ``X = {x : H_x x <= h_x}`` on every tube vertex (system.X).

Held to independent computations: a 1-D case derived by hand, HiGHS (PDHG's edges equal
HiGHS's), set properties (edges with X are edges without X; no edge ends in a cell outside X)
and ``verify`` (a changed X is caught, against the inputs record and against the tubes).
"""

import dataclasses
import json
import shutil

import numpy as np
import pytest

import tubejax as tj
from tubejax.abstraction import build_abstraction, cross_sections
from tubejax.analyses.radius_analysis import RadiusTableOptions, solve_radius_table, transition_system_at
from tubejax.errors import InputError, InputModelError
from tubejax.inputs import ProblemInputs
from tubejax.lp.evidence.verdict import highs_solve_batch
from tubejax.model.geometry import Ball, Halfspaces
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.transitions.file_format import sha256_file
from tubejax.verify.verifier import verify_directory

MAP = "1.....\n.#....\n.....2\n"
X_ROWS = {"H": [[0.0, 1.0]], "h": [1.75]}             # y <= 1.75: the top row of cells (y in [2, 3]) is outside


def _one_d(X):
    return LinearSystem(A=np.eye(1), B=np.eye(1), U=box_input_set(2.0, 1), W=Ball(1, 0.0), X=X)


@pytest.mark.parametrize("solver", ["highs", "pdhg"])
def test_hand_derived_1d_margin(solver):
    """``x+ = x + u``, ``|u| <= 2``, cells [0, 1] and [1, 2], L = 1, Z = [-a, a] (any a).

    The tube ``p + eps [-a, a]`` at step 1 must hold both successors (``u_k = p - v_k``, so
    ``t <= a eps`` from C4) and lie in the target shrunk by ``t``: ``2 a eps <= 1 - 2t``, so
    ``t* = 1/4``. With ``X = {x <= 1.75}`` the target ends at 1.75: ``2 a eps <= 0.75 - 2t``, so
    ``t* = 3/16``. The way back (into [0, 1], inside X) keeps ``1/4``.
    """
    ws = tj.box_grid([0.0], [2.0], [2])
    for X, want in ((None, 0.25), (Halfspaces([[1.0]], [1.75], "system.X"), 0.1875)):
        ts = tj.abstract(ws, _one_d(X), solver=solver, L_max=1, progress=False)
        got = {(e.src, e.dst): (e.L, e.margin, e.proof) for e in ts.edges}
        assert got[(0, 1)][:2] == (1, pytest.approx(want, abs=1e-9))
        assert got[(1, 0)][:2] == (1, pytest.approx(0.25, abs=1e-9))
        assert {p for _, _, p in got.values()} == {"exact"}


def test_x_from_python_as_a_mapping_of_rows():
    """``LinearSystem(X={"H": ..., "h": ...})`` (the config's and the file's form) is the same system as
    one given a ``tj.Halfspaces``: same rows, no difference, the same hand-derived margin; a mapping
    with other keys is refused naming the keys it needs."""
    ws = tj.box_grid([0.0], [2.0], [2])
    given = _one_d({"H": [[1.0]], "h": [1.75]})
    assert isinstance(given.X, tj.Halfspaces) and given.X.name == "system.X"
    assert given.differences(_one_d(tj.Halfspaces([[1.0]], [1.75]))) == []
    assert given.differences(_one_d(tj.Halfspaces([[1.0]], [1.5]))) == ["X"]
    ts = tj.abstract(ws, given, solver="highs", L_max=1, progress=False)
    assert {(e.src, e.dst): e.margin for e in ts.edges}[(0, 1)] == pytest.approx(0.1875, abs=1e-9)
    with pytest.raises(InputError, match=r"system\.X: expected a Halfspaces or a mapping with the keys H and h.*'b'"):
        _one_d({"H": [[1.0]], "b": [1.75]})
    with pytest.raises(InputError, match=r"system\.X\.h: expected 1 numbers"):
        _one_d({"H": [[1.0]], "h": [1.75, 2.0]})


def _inputs(map_path, X=None, method="tube", solver="highs", L_max=6):
    system = {"A": [[1.0, 0.0], [0.0, 1.0]], "B": [[0.5, 0.0], [0.0, 0.5]], "U": {"kind": "box", "bound": 1.0}}
    if X is not None:
        system["X"] = X
    return ProblemInputs.from_dict({
        "workspace": {"kind": "grid", "map_file": str(map_path)}, "system": system,
        "disturbance": {"kind": "ball", "radius": 0.1},
        "abstraction": {"L_max": L_max, "method": method, "solver": {"name": solver}},
    })


def _edges(ts):
    return {(e.src, e.dst, e.L) for e in ts.edges}


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The map with and without X (HiGHS), and with X by PDHG; the X run saved with its inputs."""
    d = tmp_path_factory.mktemp("x")
    (d / "map.txt").write_text(MAP)
    out = {}
    for name, X, solver in (("free", None, "highs"), ("X", X_ROWS, "highs"), ("X_pdhg", X_ROWS, "pdhg")):
        inp = _inputs(d / "map.txt", X, solver=solver)
        solve = highs_solve_batch if solver == "highs" else None
        ts = build_abstraction(inp.build_decomposition(), inp.build_system(), **inp.abstraction_kwargs(),
                               solve_batch=solve, progress=False)
        ts.inputs = inp.record()
        out[name] = ts
    out["X"].save(d / "run")
    return d, out


def test_x_only_removes_edges_and_none_end_outside_x(runs):
    _, r = runs
    free, withx = _edges(r["free"]), _edges(r["X"])
    assert withx < free                                   # a real restriction, and nothing new
    d = r["X"].decomposition
    above = {i for i in range(d.n_cells) if d.cells[i].vertices[:, 1].min() >= 1.75}
    assert above and not any(j in above for _, j, _ in withx)
    assert any(j in above for _, j, _ in free)


def test_pdhg_gives_highs_edges_with_x(runs):
    _, r = runs
    assert _edges(r["X_pdhg"]) == _edges(r["X"])


def test_the_x_file_verifies_and_a_changed_x_is_caught(runs, tmp_path):
    d, _ = runs
    assert verify_directory(d / "run").ok
    assert verify_directory(d / "run", complete=True).ok
    run = tmp_path / "run"
    shutil.copytree(d / "run", run)
    jpath = run / "transitions.json"
    data = json.loads(jpath.read_text())
    assert data["system"]["X"] == X_ROWS
    data["system"]["X"]["h"] = [2.5]                      # a looser X than the one the edges were built with
    data["npz_sha256"] = sha256_file(run / "transitions.npz")
    jpath.write_text(json.dumps(data))
    rep = verify_directory(run)
    assert not rep.ok and "system.X: differs from the inputs record" in "\n".join(rep.findings)


def test_a_tube_outside_x_is_caught_without_the_inputs_record(runs, tmp_path):
    """With X tightened in both the system and the inputs record, the recorded tubes leave it."""
    d, r = runs
    run = tmp_path / "run"
    shutil.copytree(d / "run", run)
    jpath = run / "transitions.json"
    data = json.loads(jpath.read_text())
    data["system"]["X"]["h"] = [1.0]
    data["inputs"]["system"]["X"]["h"] = [1.0]
    data["npz_sha256"] = sha256_file(run / "transitions.npz")
    jpath.write_text(json.dumps(data))
    rep = verify_directory(run)
    assert not rep.ok


@pytest.mark.parametrize("method", ["openloop", "exact2d"])
def test_methods_without_x_refuse_it(runs, method):
    """Refused where the configuration is read (a sweep checks every job before the first one starts),
    and by build_abstraction for a system built in Python."""
    d, r = runs
    with pytest.raises(InputModelError, match=r"abstraction\.method: expected tube for a system with X"):
        _inputs(d / "map.txt", X_ROWS, method=method)
    inp = _inputs(d / "map.txt", None, method=method)
    with pytest.raises(InputError, match=r"system\.X: method '" + method + "' does not model state constraints"):
        build_abstraction(inp.build_decomposition(), r["X"].system, **inp.abstraction_kwargs(), progress=False)


@pytest.mark.parametrize("X, field", [({"H": [[1.0, 0.0, 0.0]], "h": [1.0]}, "system.X.H"),
                                      ({"H": [[1.0, 0.0]], "h": [1.0, 2.0]}, "system.X.h"),
                                      ({"H": [[0.0, 0.0]], "h": [1.0]}, "system.X.H"),
                                      ({"H": [[1.0, 0.0]]}, "system.X.h")])
def test_bad_x_config_names_the_field(tmp_path, X, field):
    (tmp_path / "map.txt").write_text(MAP)
    with pytest.raises(InputModelError) as exc:
        _inputs(tmp_path / "map.txt", X)
    assert field in str(exc.value)


def test_every_radius_from_one_solve_keeps_x(runs):
    """The radius analysis with X: the system derived at a radius has X and equals Algorithm 2's run
    at that radius (HiGHS); the open-loop form, which has no rows for X, refuses it."""
    d, r = runs
    inp = _inputs(d / "map.txt", X_ROWS)
    dec, sysm = inp.build_decomposition(), inp.build_system()
    Z = cross_sections(dec, "box", 1.0)
    table = solve_radius_table(dec, sysm, Z=Z, solver="highs", options=RadiusTableOptions(form="tube", L_max=6))
    for rho in (0.05, 0.1):
        derived = transition_system_at(table, rho)
        assert derived.system.X is not None and derived.system.X.same_as(sysm.X)
        direct = build_abstraction(dec, dataclasses.replace(sysm, W=Ball(2, rho)), **inp.abstraction_kwargs(),
                                   solve_batch=highs_solve_batch, progress=False)
        assert _edges(derived) == _edges(direct)
    assert _edges(transition_system_at(table, 0.1)) == _edges(r["X"])
    with pytest.raises(InputError, match=r"system\.X: method 'openloop'"):
        solve_radius_table(dec, sysm, Z=Z, solver="highs", options=RadiusTableOptions(form="openloop", L_max=6))
