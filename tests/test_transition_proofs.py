"""Proof levels in transition systems: recorded, saved losslessly, re-proved (docs/math/evidence.md)."""

import json
from fractions import Fraction as F
from pathlib import Path

import numpy as np
import pytest
import shapely

from tubejax.abstraction import build_abstraction
from tubejax.lp.evidence import ExactTube, QArray, exact_tube_violation
from tubejax.transitions.transition_system import TransitionSystem
from tubejax.model.workspace import load_grid_map

MAPS = Path(__file__).resolve().parents[1] / "conf" / "workspace" / "maps"


@pytest.fixture(scope="module")
def corridor_ts(corridor_path, paper_system):
    return build_abstraction(load_grid_map(corridor_path), paper_system(0.2), L_max=10, progress=False)


def test_corridor_is_100_percent_exact(corridor_ts):
    ts = corridor_ts
    assert ts.n_edges == 78 and ts.stats["n_zero_margin"] == 8
    assert ts.stats["proof"]["exact"] == ts.n_edges and ts.stats["proof"]["float"] == 0
    assert all(e.proof == "exact" and e.violation == 0.0 for e in ts.edges)
    replaced = [k for k, e in enumerate(ts.edges) if e.exact is not None]
    assert replaced                                       # HiGHS's tubes missed by ulps: rational ones
    for k in replaced:
        e = ts.edges[k]
        assert exact_tube_violation(ts.problem(k), e.exact) <= 0
        assert all(np.array_equal(a, b) for a, b in zip(e.exact.to_float(), ts.tubes[k]))
    assert ts.to_networkx().edges[ts.edges[0].src, ts.edges[0].dst]["proof"] == "exact"


def test_save_load_keeps_rational_tubes_losslessly(corridor_ts, tmp_path):
    jpath, npath = corridor_ts.save(tmp_path)
    data = json.loads(jpath.read_text())
    assert all(e["proof"] == "exact" and "violation" not in e for e in data["edges"])
    arr = np.load(npath)
    k = next(k for k, e in enumerate(corridor_ts.edges) if e.exact is not None)
    assert arr[f"edge_{k}_exact_eps"].dtype.kind == "U" and "/" in str(arr[f"edge_{k}_exact_eps"][0])
    ts2 = TransitionSystem.load(tmp_path)
    assert ts2.edges == corridor_ts.edges
    for e1, e2 in zip(corridor_ts.edges, ts2.edges):
        if e1.exact is not None:
            assert all(a.to_fractions().tolist() == b.to_fractions().tolist() for a, b in zip(e1.exact, e2.exact))
        else:
            assert e2.exact is None
    assert np.all(ts2.verify() <= 1e-9)


def tampered_copy(ts, tmp_path, edit_json=None, edit_npz=None):
    """Save, edit, and re-record the npz's hash in the json (a careful tamperer), so that the
    checks below the file hash are what must catch it."""
    from tubejax.transitions.file_format import sha256_file

    jpath, npath = ts.save(tmp_path)
    if edit_npz:
        arrays = dict(np.load(npath))
        edit_npz(arrays)
        np.savez_compressed(npath, **arrays)
    data = json.loads(jpath.read_text())
    if edit_json:
        edit_json(data)
    data["npz_sha256"] = sha256_file(npath)
    jpath.write_text(json.dumps(data))
    return tmp_path


def test_verify_re_proves_exact_claims(corridor_ts, tmp_path):
    k = next(k for k, e in enumerate(corridor_ts.edges) if e.exact is not None)

    def nudge(arrays):                                    # an input 1e-30 beyond U: invisible in float64
        u = QArray.from_strings(arrays[f"edge_{k}_exact_u"]).to_fractions()
        u[0, 0, 0] = F(1) + F(1, 10 ** 30)
        arrays[f"edge_{k}_exact_u"] = QArray.from_fractions(u).to_strings()
        arrays[f"edge_{k}_u"] = QArray.from_fractions(u).to_float()

    ts = TransitionSystem.load(tampered_copy(corridor_ts, tmp_path / "a", edit_npz=nudge))
    with pytest.raises(AssertionError, match="claim an exact proof but fail it"):
        ts.verify()

    def bad_float(arrays):                                # the float tube no longer the rational one's rounding
        arrays[f"edge_{k}_eps"] = np.nextafter(arrays[f"edge_{k}_eps"], 10.0)

    ts = TransitionSystem.load(tampered_copy(corridor_ts, tmp_path / "b", edit_npz=bad_float))
    with pytest.raises(AssertionError, match="not the rounding"):
        ts.verify()

    def obstacle_in_s(data):       # a speck of obstacle (area 1e-10) inside a free-case safe set:
        e = corridor_ts.edges[0]   # below the float area test's threshold, caught by the exact proof
        S = corridor_ts.problem(0).safe
        c = S.vertices.mean(axis=0)
        speck = shapely.box(*(c - 5e-6), *(c + 5e-6))
        data["obstacles"].append({"kind": "wkt", "wkt": shapely.to_wkt(speck, rounding_precision=-1)})
        assert e.proof == "exact" and not corridor_ts.decomposition.obstacle_case(e.src, e.dst)

    ts = TransitionSystem.load(tampered_copy(corridor_ts, tmp_path / "c", edit_json=obstacle_in_s))
    with pytest.raises(AssertionError, match="safe set"):
        ts.verify()


def test_old_files_load_with_unknown_levels_and_can_be_re_proved(corridor_ts, tmp_path):
    def strip_json(data):
        for e in data["edges"]:
            e.pop("proof", None)
            e.pop("violation", None)

    def strip_npz(arrays):
        for key in [k for k in arrays if "_exact_" in k]:
            del arrays[key]

    d = tampered_copy(corridor_ts, tmp_path, strip_json, strip_npz)
    ts = TransitionSystem.load(d)
    assert all(e.proof is None and e.exact is None for e in ts.edges)
    assert np.all(ts.verify() <= 1e-9)                    # the float evidence still checks
    ts = TransitionSystem.load(d, prove=True)             # HiGHS's tubes re-proved, rebuilt where needed
    assert ts.stats["proof"]["exact"] == ts.n_edges
    assert [e.src for e in ts.edges] == [e.src for e in corridor_ts.edges]
    assert np.all(ts.verify() <= 1e-9)


@pytest.mark.parametrize("entry, match", [({"proof": "maybe"}, r"edges\[0\]\.proof"),
                                          ({"proof": "float", "violation": "big"}, r"edges\[0\]\.violation"),
                                          ({"proof": "float"}, r"edges\[0\]\.violation")])
def test_bad_proof_fields_are_named(corridor_ts, tmp_path, entry, match):
    def edit(data):
        data["edges"][0].pop("violation", None)
        data["edges"][0].update(entry)

    with pytest.raises(ValueError, match=match):
        TransitionSystem.load(tampered_copy(corridor_ts, tmp_path, edit_json=edit))


def test_a_half_stored_rational_tube_is_named(corridor_ts, tmp_path):
    k = next(k for k, e in enumerate(corridor_ts.edges) if e.exact is not None)
    with pytest.raises(ValueError, match=f"missing array 'edge_{k}_exact_u'"):
        TransitionSystem.load(tampered_copy(corridor_ts, tmp_path,
                                            edit_npz=lambda a: a.pop(f"edge_{k}_exact_u")))
    with pytest.raises(ValueError, match="num/den"):
        TransitionSystem.load(tampered_copy(corridor_ts, tmp_path / "x",
                                            edit_npz=lambda a: a.update({f"edge_{k}_exact_u": np.array(["x"])})))


@pytest.mark.slow
def test_paper_map_is_100_percent_exact(paper_system):
    ts = build_abstraction(load_grid_map(MAPS / "paper.txt"), paper_system(0.2), L_max=10, progress=False)
    assert ts.n_edges == 334 and ts.stats["n_zero_margin"] == 58
    assert ts.stats["proof"] == {**ts.stats["proof"], "exact": 334, "float": 0, "unknown": 0}
    for k in [k for k, e in enumerate(ts.edges) if abs(e.margin) <= 1e-9]:
        ev = ts.edges[k].exact if ts.edges[k].exact is not None else ts.tubes[k]
        assert exact_tube_violation(ts.problem(k), ev) <= 0
    assert isinstance(next(e.exact for e in ts.edges if e.exact is not None), ExactTube)
