"""`python -m tubejax verify`: a saved system is proved from its sources, and every tampering
of issue 11, finding 2 is caught (named, non-zero exit, no traceback)."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.model.geometry import Ball
from tubejax.inputs import ProblemInputs
from tubejax.lp.evidence.verdict import highs_solve_batch, highs_verdict
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem
from tubejax.transitions.file_format import FORMAT_VERSION, sha256_file
from tubejax.transitions.transition_system import TransitionFileError, TransitionSystem
from tubejax.verify.verifier import load_with_sources, verify_directory
from tubejax.model.workspace.decomposition import CellDecomposition

ROOT = Path(__file__).resolve().parents[1]
MAP = "1...\n.#..\n...2\n"


def _inputs(map_path, radius=0.2, L_max=6):
    return ProblemInputs.from_dict({
        "workspace": {"kind": "grid", "map_file": str(map_path)},
        "system": {"A": [[1.0, 0.0], [0.0, 1.0]], "B": [[0.5, 0.0], [0.0, 0.5]], "U": {"kind": "box", "bound": 1.0}},
        "disturbance": {"kind": "ball", "radius": radius},
        "abstraction": {"L_max": L_max, "solver": {"name": "highs"}},
    })


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A small abstraction saved with its inputs record (HiGHS, r = 0.2, L_max = 6)."""
    d = tmp_path_factory.mktemp("saved")
    (d / "map.txt").write_text(MAP)
    inputs = _inputs(d / "map.txt")
    ts = build_abstraction(inputs.build_decomposition(), inputs.build_system(), **inputs.abstraction_kwargs(),
                           solve_batch=highs_solve_batch, progress=False)
    ts.inputs = inputs.record()
    ts.save(d / "run")
    return d


def _copy(saved, tmp_path) -> Path:
    tmp_path.mkdir(parents=True, exist_ok=True)
    shutil.copy(saved / "map.txt", tmp_path / "map.txt")
    out = tmp_path / "run"
    shutil.copytree(saved / "run", out)
    data = json.loads((out / "transitions.json").read_text())
    data["inputs"]["workspace"]["map_file"]["resolved"] = str(tmp_path / "map.txt")
    (out / "transitions.json").write_text(json.dumps(data))
    return out


def _tamper(run: Path, edit_json=None, edit_npz=None, fix_hash=True):
    """Edit the json (a dict) and/or the npz (a dict of arrays); keep the recorded npz hash right."""
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
    if fix_hash:
        data["npz_sha256"] = sha256_file(npath)
    jpath.write_text(json.dumps(data))


def _findings(run, **kw):
    rep = verify_directory(run, **kw)
    return rep, "\n".join(rep.findings)


def test_an_honest_file_verifies(saved, tmp_path):
    run = _copy(saved, tmp_path)
    rep, _ = _findings(run, complete=True)
    assert rep.ok, rep.findings
    assert rep.n_edges > 10 and rep.proof_counts["exact"] == rep.n_edges
    assert rep.n_resolved > 0
    # load runs the cheap part and returns the rebuilt problem
    ts = load_with_sources(run)
    assert ts.n_edges == rep.n_edges and ts.inputs["disturbance"]["radius"] == 0.2


def _edge_entry(run, k):
    return json.loads((run / "transitions.json").read_text())["edges"][k]


def _plant(run, edge, tube):
    """Append ``edge`` (a json entry) and its tube to the files."""
    def ej(d):
        d["edges"].append(edge)

    def en(a):
        k = max(int(key.split("_")[1]) for key in a if key.startswith("edge_")) + 1
        a[f"edge_{k}_p"], a[f"edge_{k}_eps"], a[f"edge_{k}_u"] = tube.p, tube.eps, tube.u

    _tamper(run, ej, en)


def test_a_tube_through_a_deleted_obstacle_is_caught(saved, tmp_path):
    run = _copy(saved, tmp_path)
    ts = load_with_sources(run)
    d = ts.decomposition
    free = CellDecomposition(d.cells, d.labels, (), d.grid, "no obstacle")       # the obstacle deleted
    have = {(e.src, e.dst) for e in ts.edges}
    planted = None
    for i in range(d.n_cells):
        for j in range(d.n_cells):
            if i == j or (i, j) in have or not d.obstacle_case(i, j):
                continue
            for L in range(1, 7):
                v = highs_verdict(pair_problem(free, ts.system, ts.Z[i], i, j, L))
                if v.status == "edge":
                    planted = ({"from": i, "to": j, "L": L, "margin": v.margin, "provenance": "highs",
                                "proof": "exact"}, v.tube)
                    break
            if planted:
                break
        if planted:
            break
    assert planted is not None
    _plant(run, *planted)
    _tamper(run, lambda data: data.update(obstacles=[]))
    rep, text = _findings(run)
    assert not rep.ok
    assert "obstacles: the file lists 0, the workspace has 1" in text
    e = planted[0]
    assert f"{e['from']}->{e['to']} (L={e['L']}): the stored evidence violates Problem 2" in text
    with pytest.raises(TransitionFileError, match="obstacles"):
        load_with_sources(run)


def test_an_edge_planted_from_a_W0_run_is_caught(saved, tmp_path):
    run = _copy(saved, tmp_path)
    ts = load_with_sources(run)
    s0 = LinearSystem(A=ts.system.A, B=ts.system.B, U=ts.system.U, W=Ball(2, 0.0))
    have = {(e.src, e.dst): e.L for e in ts.edges}
    planted = None
    for (i, j), L in sorted(have.items()):
        if L > 1:                        # at W = 0 a shorter horizon may work
            v = highs_verdict(pair_problem(ts.decomposition, s0, ts.Z[i], i, j, L - 1))
            if v.status == "edge":
                planted = (i, j, L - 1, v)
                break
    assert planted is not None
    i, j, L, v = planted

    def ej(data):
        data["system"]["W"]["radius"] = 0.0
        k = next(k for k, e in enumerate(data["edges"]) if (e["from"], e["to"]) == (i, j))
        data["edges"][k].update(L=L, margin=v.margin)

    def en(a):
        k = next(k for k, e in enumerate(ts.edges) if (e.src, e.dst) == (i, j))
        a[f"edge_{k}_p"], a[f"edge_{k}_eps"], a[f"edge_{k}_u"] = v.tube.p, v.tube.eps, v.tube.u
        for name in ("p", "eps", "u"):
            a.pop(f"edge_{k}_exact_{name}", None)

    _tamper(run, ej, en)
    rep, text = _findings(run)
    assert "system.W" in text
    assert f"{i}->{j} (L={L}): the stored evidence violates Problem 2" in text


def test_deleted_edges_are_found_by_complete(saved, tmp_path):
    run = _copy(saved, tmp_path)
    ts = load_with_sources(run)
    gone = ts.edges[3]
    del ts.edges[3], ts.tubes[3]
    ts.stats["n_edges"] = ts.n_edges                     # a careful tamperer fixes the counts too
    ts.save(run)
    rep, _ = _findings(run)
    assert rep.ok                                        # the cheap checks cannot see a deletion...
    rep, text = _findings(run, complete=True)            # ...re-solving every non-edge does
    assert f"pair {gone.src}->{gone.dst}: a transition exists at L={gone.L}, missing from the file" in text


@pytest.mark.parametrize("tamper, expect", [
    (lambda d: d["cells"][0].update(label=d["cells"][-1]["label"]) or d["cells"][-1].update(label="1"),
     "cells[0].label: the file says '2', the workspace says '1'"),
    (lambda d: d["edges"][0].update(margin=d["edges"][0]["margin"] + 0.05), "margin"),
    (lambda d: d["edges"][0].update(provenance="pdhg+highs"), "provenance 'pdhg+highs' is not one"),
    (lambda d: d.update(method="exact2d"), "unexpected array 'edge_0_eps'"),
    (lambda d: d["edges"][1].update(L=d["edges"][1]["L"] + 1), "array 'edge_1_p': expected float shape"),
    (lambda d: d["stats"].update(n_edges=3), "stats.n_edges"),
])
def test_tampered_fields_are_named(saved, tmp_path, tamper, expect):
    run = _copy(saved, tmp_path)
    _tamper(run, tamper)
    rep, text = _findings(run)
    assert not rep.ok and expect in text


def test_method_changed_to_exact2d_is_caught(saved, tmp_path):
    """exact2d stores no tubes: a file switched to it, evidence removed, must still not pass."""
    run = _copy(saved, tmp_path)

    def drop_evidence(a):
        for key in [k for k in a if k.startswith("edge_")]:
            del a[key]

    _tamper(run, lambda d: d.update(method="exact2d"), drop_evidence)
    rep, text = _findings(run)
    assert "method: the file says 'exact2d', its inputs record says 'tube'" in text


def test_damaged_files_are_named_not_tracebacks(saved, tmp_path):
    run = _copy(saved, tmp_path)
    # format_version = 99 in the npz
    _tamper(run, edit_npz=lambda a: a.update(format_version=np.array(99)))
    assert f"array 'format_version' is 99, expected {FORMAT_VERSION}" in "\n".join(verify_directory(run).findings)
    # an npz key removed
    run = _copy(saved, tmp_path / "b")
    _tamper(run, edit_npz=lambda a: a.pop("edge_2_u"))
    assert "missing array 'edge_2_u'" in "\n".join(verify_directory(run).findings)
    # a fake edge appended to the json only
    run = _copy(saved, tmp_path / "c")
    n = len(json.loads((run / "transitions.json").read_text())["edges"])
    _tamper(run, lambda d: d["edges"].append(dict(d["edges"][0], to=d["edges"][0]["to"])))
    assert f"missing array 'edge_{n}_p'" in "\n".join(verify_directory(run).findings)
    # an npz from elsewhere (hash not fixed)
    run = _copy(saved, tmp_path / "d")
    _tamper(run, edit_npz=lambda a: a.update(Z_0=a["Z_0"] * 2), fix_hash=False)
    assert "SHA-256 differs" in "\n".join(verify_directory(run).findings)
    # a truncated json
    run = _copy(saved, tmp_path / "e")
    text = (run / "transitions.json").read_text()
    (run / "transitions.json").write_text(text[: len(text) // 2])
    assert "not valid JSON" in "\n".join(verify_directory(run).findings)
    # the map changed since the run
    run = _copy(saved, tmp_path / "f")
    (tmp_path / "f" / "map.txt").write_text(MAP.replace("#", "."))
    assert "sha256" in "\n".join(verify_directory(run).findings).lower()
    # not a directory of a run
    assert "no such file" in "\n".join(verify_directory(tmp_path / "nowhere").findings) or \
        "no such directory" in "\n".join(verify_directory(tmp_path / "nowhere").findings)


def test_the_command_line_exits_nonzero_and_names_the_edge(saved, tmp_path):
    run = _copy(saved, tmp_path)
    ok = subprocess.run([sys.executable, "-m", "tubejax", "verify", str(run), "--quiet"], cwd=ROOT,
                        capture_output=True, text=True, timeout=300)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert ok.stdout.startswith("verify OK")
    _tamper(run, lambda d: d["edges"][0].update(margin=0.9))
    bad = subprocess.run([sys.executable, "-m", "tubejax", "verify", str(run), "--quiet"], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 1
    assert "FAIL edges[0]" in bad.stdout and "verify FAILED" in bad.stdout
    assert "Traceback" not in bad.stdout + bad.stderr
