"""The transition system at a requested radius, derived from one rho* solve, equals Algorithm 2's
run at that radius (HiGHS, independently), ties included; the same for every smaller L_max; each
edge's rho_star is HiGHS's critical disturbance; files with rho_star load and verify, tampering
is caught, old files stay readable."""

import json


import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.model.geometry import Ball
from tubejax.inputs import ProblemInputs
from tubejax.lp.evidence.verdict import highs_solve_batch
from tubejax.lp.evidence.verdict import highs_solver
from tubejax.analyses.radius_analysis import n_edges_vs_L_max, record_at_radius, transition_system_at
from tubejax.model.system import LinearSystem
from tubejax.transitions.transition_system import TransitionSystem
from tubejax.verify.verifier import verify_directory

openloop_solve_batch = highs_solver("openloop")

SOLVE = {"tube": highs_solve_batch, "openloop": openloop_solve_batch}
RADII = (0.0, 0.05, 0.1, 0.2, 0.25, 0.3)


def _direct(corridor, form, r, L_max=10):
    dec, sysm, _ = corridor
    s_r = LinearSystem(A=sysm.A, B=sysm.B, U=sysm.U, W=Ball(2, r))
    return build_abstraction(dec, s_r, L_max=L_max, solve_batch=SOLVE[form], progress=False, method=form)


def _edges(ts):
    return {(e.src, e.dst): e.L for e in ts.edges}


@pytest.fixture(scope="module")
def derived(pdhg_tables):
    """Systems derived from the batched tables at every radius (cached per (form, r))."""
    cache = {}

    def get(form, r):
        if (form, r) not in cache:
            cache[form, r] = transition_system_at(pdhg_tables[form], r)
        return cache[form, r]
    return get


@pytest.mark.parametrize("r", RADII)
@pytest.mark.parametrize("form", ["tube", "openloop"])
def test_derived_system_equals_algorithm_2(corridor, derived, pdhg_tables, highs_tables, form, r):
    ts = derived(form, r)
    direct = _direct(corridor, form, r)
    assert _edges(ts) == _edges(direct)
    pdhg_tables[form].refine()                                   # the exact curve agrees at r too
    assert pdhg_tables[form].n_edges()(r) == direct.n_edges
    assert ts.system.W.radius == r and ts.method == form and ts.stats["n_edges"] == direct.n_edges
    ts.verify()                                                  # every stored tube at this radius, float64
    assert all(e.proof in ("exact", "float") for e in ts.edges)
    crit = highs_tables[form].critical()
    ref = {(int(i), int(j)): v for i, j, v in zip(crit.src, crit.dst, crit.value)}
    for e in ts.edges:
        assert e.rho_star >= r and abs(e.rho_star - max(ref[e.src, e.dst], r)) <= 1e-9
    assert ts.stats["n_lps"] <= highs_tables[form].n_instances     # most non-edges are certified


def test_ties_are_covered_and_decided_by_highs(highs_tables, derived):
    """On the grid map rho* lands exactly on round radii: the tests above do cover ties."""
    for form, r in (("tube", 0.2), ("tube", 0.3), ("openloop", 0.1)):
        assert np.any(np.abs(highs_tables[form].value - r) <= 1e-9)
        assert derived(form, r).stats["n_ties"] > 0


@pytest.mark.parametrize("L_max", [3, 5, 7])
def test_every_smaller_L_max_from_the_same_table(corridor, pdhg_tables, derived, L_max):
    ts = transition_system_at(pdhg_tables["tube"], 0.2, L_max=L_max)
    full = derived("tube", 0.2)
    assert _edges(ts) == {k: L for k, L in _edges(full).items() if L <= L_max}
    assert _edges(ts) == _edges(_direct(corridor, "tube", 0.2, L_max))
    assert n_edges_vs_L_max(full)[L_max - 1] == ts.n_edges


def _saved(corridor_path, derived, tmp_path, r=0.2):
    rec = ProblemInputs.from_dict({
        "workspace": {"kind": "grid", "map_file": str(corridor_path)},
        "system": {"A": [[1.0, 0.0], [0.0, 1.0]], "B": [[0.5, 0.0], [0.0, 0.5]], "U": {"kind": "box", "bound": 1.0}},
        "disturbance": {"kind": "ball", "radius": 0.2},
        "abstraction": {"L_max": 10, "solver": {"name": "pdhg"}},
    }).record()
    ts = derived("tube", r)
    ts.inputs = ProblemInputs.from_record(record_at_radius(rec, r)).record()
    ts.save(tmp_path / "run")
    return tmp_path / "run"


def test_rho_star_round_trip_and_verify(corridor_path, derived, tmp_path):
    run = _saved(corridor_path, derived, tmp_path)
    back = TransitionSystem.load(run)
    assert [e.rho_star for e in back.edges] == [e.rho_star for e in derived("tube", 0.2).edges]
    assert back.to_networkx().edges[back.edges[0].src, back.edges[0].dst]["rho_star"] == back.edges[0].rho_star
    rep = verify_directory(run)
    assert rep.ok, rep.findings
    assert "rho_star of 78 edges checked" in rep.summary


@pytest.mark.parametrize("value, expect", [
    (0.1, "rho_star 0.1 is below the file's radius 0.2"),
    (0.7, "rho_star 0.7 is above 0.5"),
    ("0.3", "field 'edges[3].rho_star': expected a finite number"),
])
def test_tampered_rho_star_is_caught(corridor_path, derived, tmp_path, value, expect):
    run = _saved(corridor_path, derived, tmp_path)
    data = json.loads((run / "transitions.json").read_text())
    data["edges"][3]["rho_star"] = value
    (run / "transitions.json").write_text(json.dumps(data))
    rep = verify_directory(run)
    assert not rep.ok and expect in "\n".join(rep.findings)


def test_complete_re_solves_rho_star(corridor_path, derived, tmp_path):
    run = _saved(corridor_path, derived, tmp_path)
    data = json.loads((run / "transitions.json").read_text())
    e = data["edges"][5]
    e["rho_star"] = e["rho_star"] + 1e-3 if e["rho_star"] < 0.45 else e["rho_star"] - 1e-3
    (run / "transitions.json").write_text(json.dumps(data))
    assert verify_directory(run).ok                          # within the cheap bounds
    rep = verify_directory(run, complete=True)
    assert not rep.ok and len(rep.findings) == 1
    assert f"edges[5] {e['from']}->{e['to']} (L={e['L']}): rho_star" in rep.findings[0]
    assert "HiGHS gives" in rep.findings[0]


def test_files_without_rho_star_stay_readable(corridor_path, derived, tmp_path):
    run = _saved(corridor_path, derived, tmp_path)
    data = json.loads((run / "transitions.json").read_text())
    for e in data["edges"]:
        del e["rho_star"]
    (run / "transitions.json").write_text(json.dumps(data))
    back = TransitionSystem.load(run)
    assert all(e.rho_star is None for e in back.edges) and "rho_star" not in back.edges[0].to_json()
    assert verify_directory(run).ok


def test_radius_zero_of_a_polytope_is_refused(corridor):
    from tubejax.model.geometry import Polytope
    from tubejax.analyses.radius_analysis import RadiusTableOptions, solve_radius_table

    dec, sysm, Z = corridor
    box = LinearSystem(A=sysm.A, B=sysm.B, U=sysm.U, W=Polytope.box(-0.1 * np.ones(2), 0.1 * np.ones(2)))
    t = solve_radius_table(dec, box, Z=Z, solver="highs", options=RadiusTableOptions(L_max=1))
    with pytest.raises(ValueError, match="use a radius > 0"):
        transition_system_at(t, 0.0)
    with pytest.raises(ValueError, match="a box disturbance of size 0 is not a valid W"):
        record_at_radius({"disturbance": {"kind": "box", "half_width": 0.1}}, 0.0)

