"""Issue 21: hostile saved runs. Every file below is tampered the way a hostile user would (the
npz hash in the json kept right), and ``verify`` and the simulator's loader
(:func:`tubejax.verify.verifier.load_checked`) must refuse it with one line naming the file, field or
value -- never a traceback, never a pass. The honest files pass, so each check can fail."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.inputs import ProblemInputs
from tubejax.lp.evidence.verdict import highs_solve_batch
from tubejax.transitions.file_format import TransitionFileError, sha256_file
from tubejax.transitions.transition_system import TransitionSystem
from tubejax.verify.verifier import check_run, load_checked, verify_directory

MAP = "1..\n.#.\n..2\n"                 # conf/workspace/maps/tiny.txt: 8 cells, every edge has its reverse


def _inputs(map_path, shard=(1, 0)):
    return ProblemInputs.from_dict({
        "workspace": {"kind": "grid", "map_file": str(map_path)},
        "system": {"A": [[1.0, 0.0], [0.0, 1.0]], "B": [[0.5, 0.0], [0.0, 0.5]], "U": {"kind": "box", "bound": 1.0}},
        "disturbance": {"kind": "ball", "radius": 0.2},
        "abstraction": {"L_max": 6, "solver": {"name": "highs"}, "shard": {"count": shard[0], "index": shard[1]}},
    })


def _save(d: Path, shard=(1, 0)) -> Path:
    d.mkdir(parents=True, exist_ok=True)
    (d / "map.txt").write_text(MAP)
    inputs = _inputs(d / "map.txt", shard)
    ts = build_abstraction(inputs.build_decomposition(), inputs.build_system(), **inputs.abstraction_kwargs(),
                           solve_batch=highs_solve_batch, progress=False, shard=shard)
    ts.inputs = inputs.record()
    ts.save(d / "run")
    return d


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """The tiny map's abstraction (HiGHS, r = 0.2, L_max = 6) with its inputs record, and shard 0 of 2 of it."""
    root = tmp_path_factory.mktemp("claims")
    return _save(root / "whole"), _save(root / "shard", shard=(2, 0))


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    run = dst / "run"
    data = json.loads((run / "transitions.json").read_text())
    data["inputs"]["workspace"]["map_file"]["resolved"] = str(dst / "map.txt")
    (run / "transitions.json").write_text(json.dumps(data))
    return run


def _tamper(run: Path, edit_json=None, edit_npz=None):
    """Edit the json (a dict) and/or the npz (a dict of arrays), keeping the recorded npz hash right."""
    jpath, npath = run / "transitions.json", run / "transitions.npz"
    if edit_npz is not None:
        with np.load(npath) as z:
            arrays = {k: z[k] for k in z.files}
        edit_npz(arrays)
        with open(npath, "wb") as f:
            np.savez_compressed(f, **arrays)
    data = json.loads(jpath.read_text())
    if edit_json is not None:
        edit_json(data)
    data["npz_sha256"] = sha256_file(npath)
    jpath.write_text(json.dumps(data))


def _refused(run: Path, expect: str, complete: bool = False) -> None:
    """verify (and --complete) and load_checked all refuse ``run`` naming ``expect``."""
    for c in {False, complete}:
        rep = verify_directory(run, complete=c)
        assert not rep.ok and any(expect in f for f in rep.findings), rep.findings
    with pytest.raises(TransitionFileError, match=None) as info:
        load_checked(run)
    assert expect in str(info.value) or expect in "\n".join(check_run(run).findings)


def test_honest_runs_pass(saved, tmp_path):
    whole, shard = saved
    for src, name in ((whole, "a"), (shard, "b")):
        run = _copy(src, tmp_path / name)
        rep = verify_directory(run)
        assert rep.ok, rep.findings
        ts = load_checked(run)
        assert ts.n_edges == rep.n_edges > 0
    # the shard holds exactly the edges of its sources: fewer than the whole run, and some
    whole_ts, shard_ts = load_checked(_copy(whole, tmp_path / "c")), load_checked(_copy(shard, tmp_path / "d"))
    assert 0 < shard_ts.n_edges < whole_ts.n_edges


def test_a_self_loop_is_refused_not_a_traceback(saved, tmp_path):
    run = _copy(saved[0], tmp_path / "x")
    n = len(json.loads((run / "transitions.json").read_text())["edges"])

    def loop(d):
        d["edges"].append(dict(d["edges"][0], to=d["edges"][0]["from"]))
        d["stats"]["n_edges"] += 1

    def tube(a):
        for name in ("p", "eps", "u"):
            a[f"edge_{n}_{name}"] = a[f"edge_0_{name}"]

    _tamper(run, loop, tube)
    _refused(run, f"field 'edges[{n}]': 0 -> 0 is a self-pair", complete=True)


def test_a_truncated_npz_with_its_hash_updated_is_refused(saved, tmp_path):
    run = _copy(saved[0], tmp_path / "x")
    npath = run / "transitions.npz"
    data = npath.read_bytes()
    npath.write_bytes(data[: len(data) // 2])
    _tamper(run)                                            # the hash of the cut file recorded
    _refused(run, "cannot read the npz", complete=True)
    assert "damaged or truncated" in verify_directory(run).findings[0]


def test_inputs_naming_another_map_with_its_hash_is_refused(saved, tmp_path):
    run = _copy(saved[0], tmp_path / "x")
    other = tmp_path / "x" / "other.txt"
    other.write_text("1.2\n")                               # 3 cells; the file's edges name cells up to 7

    def point_elsewhere(d):
        f = d["inputs"]["workspace"]["map_file"]
        f.update(path="other.txt", resolved=str(other), sha256=sha256_file(other))

    _tamper(run, point_elsewhere)
    _refused(run, "cells: the file lists 8 cells, the workspace has 3", complete=True)
    assert any("edges: not checked" in f for f in verify_directory(run).findings)


@pytest.mark.parametrize("edit, expect", [
    (lambda d: d["edges"][0].update(rho_star=0.45), "does not come from a radius analysis"),
    (lambda d: d["edges"][0].update(violation=0.5), "'edges[0].violation' is 0.5, but the edge claims proof 'exact'"),
    (lambda d: d["edges"][0].update(proof="float", violation=0.5), "'edges[0].violation' is 0.5, above the 1e-09"),
    (lambda d: d["edges"][0].pop("proof") and d["edges"][0].update(violation=1e-12), "has no proof level"),
    (lambda d: d["edges"][0].update(provenance="magic"), "provenance 'magic' is not one"),
    (lambda d: d["edges"][0].update(provenance="pdhg+highs"), "provenance 'pdhg+highs' is not one"),
    (lambda d: d.update(inputs=None), "no inputs record"),
])
def test_claims_never_computed_are_refused(saved, tmp_path, edit, expect):
    run = _copy(saved[0], tmp_path / "x")
    _tamper(run, edit)
    _refused(run, expect)


def test_swapped_from_and_to_is_refused(saved, tmp_path):
    """On this map every edge has its reverse: swapping from/to duplicates a pair (a cheap check);
    the swapped edge's tube does not start in its new source (the evidence check)."""
    run = _copy(saved[0], tmp_path / "x")

    def swap(d):
        e = d["edges"][0]
        e["from"], e["to"] = e["to"], e["from"]

    _tamper(run, swap)
    _refused(run, "a second edge for the same pair")
    assert any("edges[0]" in f and "violates Problem 2" in f for f in verify_directory(run).findings)


def test_a_shard_claim_over_every_edge_is_refused(saved, tmp_path):
    run = _copy(saved[0], tmp_path / "x")
    _tamper(run, lambda d: d["inputs"]["abstraction"]["shard"].update(count=2, index=0))
    _refused(run, "the file claims shard 0 of 2", complete=True)
    # and the honest shard 1 of 2 holds none of shard 0's sources
    run = _copy(saved[1], tmp_path / "y")
    _tamper(run, lambda d: d["inputs"]["abstraction"]["shard"].update(index=1))
    _refused(run, "the file claims shard 1 of 2")


def _metrics(run: Path) -> dict:
    """The row experiments/abstract.py writes, computed here from the honest files."""
    d = json.loads((run / "transitions.json").read_text())
    edges, st = d["edges"], d["stats"]
    return {"method": "tube", "solver": "highs", "system": "custom", "disturbance": "ball", "radius": 0.2,
            "zshape": "box", "L_max": 6, "pruning": True, "n_cells": len(d["cells"]), "n_edges": len(edges),
            "n_lps": st["n_lps"], "seconds": st["seconds"], "mean_L": sum(e["L"] for e in edges) / len(edges),
            "mean_margin": sum(e["margin"] for e in edges) / len(edges),
            "edges": [[e["from"], e["to"], e["L"]] for e in edges], "an_unknown_key": 1}


def test_metrics_json_is_checked_against_the_files(saved, tmp_path):
    run = _copy(saved[0], tmp_path / "x")
    m = _metrics(run)
    m["system"] = json.loads((run / "transitions.json").read_text())["inputs"]["system"]["name"]
    (run / "metrics.json").write_text(json.dumps(m))
    assert verify_directory(run).ok                              # the honest row passes
    (run / "metrics.json").write_text(json.dumps(dict(m, n_edges=999)))
    _refused(run, "field 'n_edges' is 999, the transitions file gives")
    # a cut edge list (the npz and stats.n_edges made consistent) beside the old metrics.json
    (run / "metrics.json").write_text(json.dumps(m))
    ts = TransitionSystem.load(run)
    del ts.edges[-1], ts.tubes[-1]
    ts.stats["n_edges"] = ts.n_edges
    ts.save(run)
    rep = verify_directory(run)
    assert "field 'edges' differs" in "\n".join(rep.findings) and "field 'n_edges'" in "\n".join(rep.findings)
    (run / "metrics.json").write_text("{not json")
    _refused(run, "metrics.json: cannot read it")


def test_metrics_of_a_run_without_edges_are_json_and_verify(saved, tmp_path):
    """``mean_L`` and ``mean_margin`` of a run without edges are written as ``null`` (bare ``NaN`` is
    not JSON), and ``verify`` reads ``null`` as the NaN the transitions file gives."""
    import sys
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments"))
    try:
        from common import write_json
    finally:
        sys.path.remove(str(Path(__file__).resolve().parents[1] / "experiments"))
    run = _copy(saved[0], tmp_path / "x")
    m = dict(_metrics(run), n_edges=0, edges=[], mean_L=float("nan"), mean_margin=float("nan"))
    ts = TransitionSystem.load(run)
    del ts.edges[:], ts.tubes[:]
    ts.stats["n_edges"] = 0
    ts.save(run)
    write_json(run / "metrics.json", m)
    text = (run / "metrics.json").read_text()
    assert "NaN" not in text
    row = json.loads(text, parse_constant=lambda c: pytest.fail(f"bare {c} in metrics.json"))
    assert row["mean_L"] is None and row["mean_margin"] is None
    findings = "\n".join(verify_directory(run).findings)
    assert "mean_L" not in findings and "mean_margin" not in findings
    write_json(run / "metrics.json", dict(m, mean_L=3.0))            # a claimed mean over no edges
    assert "field 'mean_L' is 3.0" in "\n".join(verify_directory(run).findings)
