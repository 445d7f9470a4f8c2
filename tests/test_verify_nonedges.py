"""Non-edges keep their evidence, and ``verify --complete`` re-checks it.

A run on an open 2 x 7 grid whose three-column moves are zero-margin edges at ``L = 10``: their
``L = 9`` instances are refused by HiGHS at ``-0.0155`` (a float64-checked dual bound), others by
their translation class. Exact certificates are made here by deciding a few instances exactly;
``verify --complete`` must re-check each kind -- exact certificates and translates without a
solve -- and name a record that does not hold: a tampered certificate, a translate whose
"representative" is no translate of it, a dual bound below HiGHS's optimum, a record that
contradicts an edge.
"""

import json
import shutil

from pathlib import Path

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction, cross_sections
from tubejax.inputs import ProblemInputs
from tubejax.lp.evidence.decide import Refutation, decide_exactly
from tubejax.lp.evidence.verdict import highs_solve_batch
from tubejax.lp.declarations.tube_lp import build_tube_lp
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.model.problem import pair_problem
from tubejax.transitions.records import NonEdges
from tubejax.transitions.transition_system import TransitionSystem
from tubejax.verify.verifier import load_with_sources, verify_directory

MAP = "\n".join(["." * 7] * 2) + "\n"


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    d = tmp_path_factory.mktemp("nonedges")
    (d / "map.txt").write_text(MAP)
    inputs = ProblemInputs.from_dict({
        "workspace": {"kind": "grid", "map_file": str(d / "map.txt")},
        "system": {"A": [[1.0, 0.0], [0.0, 1.0]], "B": [[0.5, 0.0], [0.0, 0.5]], "U": {"kind": "box", "bound": 1.0}},
        "disturbance": {"kind": "ball", "radius": 0.2},
        "abstraction": {"L_max": 10, "solver": {"name": "highs"}},
    })
    ts = build_abstraction(inputs.build_decomposition(), inputs.build_system(), **inputs.abstraction_kwargs(),
                           solve_batch=highs_solve_batch, progress=False)
    ts.inputs = inputs.record()
    ts.save(d / "run")
    return d, ts


def _rewrite(saved, tmp_path, edit) -> Path:
    """A copy of the run whose non-edge records ``edit(ts, index)`` changed (re-saved consistently)."""
    d, _ = saved
    shutil.copy(d / "map.txt", tmp_path / "map.txt")
    ts = load_with_sources(d / "run")           # the problem as the run built it (rows in its order)
    idx = ts.nonedges.index()
    edit(ts, idx)
    keys = sorted(idx)
    ts.nonedges = NonEdges(*(np.array([k[c] for k in keys], np.int64) for c in range(3)), [idx[k] for k in keys])
    ts.save(tmp_path / "run")
    data = json.loads((tmp_path / "run" / "transitions.json").read_text())
    data["inputs"]["workspace"]["map_file"]["resolved"] = str(tmp_path / "map.txt")
    (tmp_path / "run" / "transitions.json").write_text(json.dumps(data))
    return tmp_path / "run"


def _exact(ts, i, j, L) -> Refutation:
    """An exact certificate for ``(i, j, L)``, on the problem as the run built it (``Z`` made by its
    kind, as verify rebuilds it: a certificate names the rows of that LP)."""
    Z = cross_sections(ts.decomposition, "box", 1.0)[i]
    prob = pair_problem(ts.decomposition, ts.system, Z, i, j, L)
    lp = build_tube_lp(prob)
    res = solve_margin_lp(lp, basis_min_margin=-np.inf)
    d = decide_exactly(prob, lp, res._replace(margin=-1e-13))
    assert d.status == "infeasible" and d.refutation.kind == "exact"
    return d.refutation


def test_every_refusal_is_recorded_and_verify_rechecks_them(saved):
    d, ts = saved
    ne = ts.nonedges
    assert len(ne) == ts.stats["n_lps"] - ts.n_edges and set(ne.counts()) >= {"dual", "translate"}
    rep = verify_directory(d / "run", complete=True)
    assert rep.ok, rep.findings
    assert "non-edges settled by their recorded evidence" in rep.summary


def test_exact_certificates_are_rechecked_without_a_solve_and_tampering_is_named(saved, tmp_path):
    _, ts = saved
    target = (1, 4, 9)

    def exact(ts, idx):
        idx[target] = _exact(ts, *target)

    (tmp_path / "ok").mkdir()
    run = _rewrite(saved, tmp_path / "ok", exact)
    rep = verify_directory(run, complete=True)
    assert rep.ok, rep.findings

    def tampered(ts, idx):
        r = _exact(ts, *target)
        y = {k: v / 1000 if n == 0 else v for n, (k, v) in enumerate(r.certificate.items())}
        idx[target] = r._replace(certificate=y)

    (tmp_path / "bad").mkdir()
    rep = verify_directory(_rewrite(saved, tmp_path / "bad", tampered), complete=True)
    assert any("1->4 at L=9: its recorded exact refutation does not hold" in f for f in rep.findings), rep.findings


def test_false_translates_dual_bounds_and_contradictions_are_named(saved, tmp_path):
    _, ts = saved
    idx = ts.nonedges.index()
    tr = next(k for k, r in idx.items() if r.kind == "translate")
    du = next(k for k, r in idx.items() if r.kind == "dual")
    edge = ts.edges[0]

    other = next(k for k, r in idx.items() if k[2] == tr[2] and r.kind != "translate"
                 and k[1] - k[0] != tr[1] - tr[0])                          # another offset: not its class

    def edit(ts, idx):
        idx[tr] = idx[tr]._replace(certificate=(other[0], other[1]))
        idx[du] = idx[du]._replace(bound=idx[du].bound - 0.5)                  # below the optimum
        idx[(edge.src, edge.dst, edge.L)] = Refutation("dual", -1.0)           # refutes an edge

    rep = verify_directory(_rewrite(saved, tmp_path, edit), complete=True)
    text = "\n".join(rep.findings)
    assert f"{tr[0]}->{tr[1]} at L={tr[2]}: its recorded translate refutation does not hold" in text
    assert f"{du[0]}->{du[1]} at L={du[2]}: recorded dual bound" in text
    assert f"non-edge record {edge.src}->{edge.dst} at L={edge.L}: the pair has an edge" in text


def test_malformed_records_are_refused_on_load(saved, tmp_path):
    d, _ = saved
    from tubejax.transitions.file_format import TransitionFileError
    arrays = dict(np.load(d / "run" / "transitions.npz"))
    arrays["nonedge_kind"] = np.full_like(arrays["nonedge_kind"], 9)
    shutil.copytree(d / "run", tmp_path / "run")
    np.savez_compressed(tmp_path / "run" / "transitions.npz", **arrays)
    data = json.loads((tmp_path / "run" / "transitions.json").read_text())
    from tubejax.transitions.file_format import sha256_file
    data["npz_sha256"] = sha256_file(tmp_path / "run" / "transitions.npz")
    (tmp_path / "run" / "transitions.json").write_text(json.dumps(data))
    with pytest.raises(TransitionFileError, match="nonedge_kind.*not a known kind"):
        TransitionSystem.load(tmp_path / "run")



def test_certificates_of_other_rows_are_re_solved_not_read(saved, tmp_path):
    """A file records which row families its certificates index (``certificate_rows``); a file of
    another declaration (here: rows named in another order) has its exact records re-solved."""
    _, ts = saved
    target = (1, 4, 9)

    def tampered(ts, idx):
        r = _exact(ts, *target)
        idx[target] = r._replace(certificate={k: v / 1000 if n == 0 else v
                                              for n, (k, v) in enumerate(r.certificate.items())})

    run = _rewrite(saved, tmp_path, tampered)
    data = json.loads((run / "transitions.json").read_text())
    assert data["version"] == 4 and data["certificate_rows"] == ["safe", "target", "dynamics"]
    data["certificate_rows"] = ["target", "safe", "dynamics"]
    (run / "transitions.json").write_text(json.dumps(data))
    assert TransitionSystem.load(run).certificate_rows == ("target", "safe", "dynamics")
    rep = verify_directory(run, complete=True)
    assert rep.ok, rep.findings                       # the bad certificate is not read: 1->4 at L=9 is re-solved
