"""zshape=learned / learned_pair in experiments/abstract.py: learned_z.json saved with the run, recorded by
SHA-256, reloaded by verify (tampering refused), bad values refused clearly, the learning deterministic."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tubejax.errors import InputError
from tubejax.inputs import ProblemInputs
from tubejax.verify.verifier import verify_directory
from tubejax.model.workspace.gridmap import parse_grid_map
from tubejax.analyses.zshape import LearnOptions, load_z_table
from tubejax.analyses.zshape.learn_run import learn_table
from tubejax.model.zshape.z_table import assignment_from_table

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / "tests" / "data" / "tiny.txt"


def run_app(*overrides, workspace=f"workspace.map_file={TINY}"):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}          # this checkout's tubejax, not an installed one
    return subprocess.run([sys.executable, str(ROOT / "experiments" / "abstract.py"), "progress=false",
                           workspace, "solver=highs", "L_max=4", *overrides],
                          cwd=ROOT, capture_output=True, text=True, timeout=600, env=env)


@pytest.fixture(scope="module")
def learned_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("learned") / "run"
    p = run_app("zshape=learned", "zshape.steps=2", f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr
    return out, p


def test_learned_run_saves_records_and_verifies(learned_run):
    out, p = learned_run
    assert "learned_z.json (the learned Z)" in p.stdout
    assert "learning Z (learned) step 2" in (out / "abstract.log").read_text()
    doc = json.loads((out / "transitions.json").read_text())
    rec = doc["inputs"]["zshape"]
    assert rec["kind"] == "learned" and rec["file"]["path"] == "learned_z.json"
    table = load_z_table(out / "learned_z.json", sha256=rec["file"]["sha256"])
    assert table.mode == "learned" and table.n_shapes == 1 and table.learning["steps"] == 2
    assert all(f["n_compiles"] == 1 for f in table.learning["families"])       # no recompiles while learning
    assert doc["stats"]["zshape"] == "learned" and doc["stats"]["n_edges"] > 0
    report = verify_directory(out, complete=True)
    assert report.ok, report.findings
    assert report.proof_counts["exact"] == doc["stats"]["n_edges"]


def test_tampered_learned_z_fails_verify(learned_run, tmp_path):
    out, _ = learned_run
    copy = tmp_path / "copy"
    copy.mkdir()
    for name in ("transitions.json", "transitions.npz", "learned_z.json"):
        (copy / name).write_bytes((out / name).read_bytes())
    assert verify_directory(copy).ok                               # a copied run checks its own learned_z.json
    doc = json.loads((copy / "learned_z.json").read_text())
    doc["shapes"][0]["vertices"][0][0] *= 1.001                   # still a valid Z, but not the recorded one
    (copy / "learned_z.json").write_text(json.dumps(doc))
    report = verify_directory(copy)
    assert not report.ok
    assert "zshape.file" in report.findings[0] and str(copy / "learned_z.json") in report.findings[0]
    assert "changed since it was recorded" in report.findings[0]


def test_learned_pair_run_reuses_a_file_and_verifies(learned_run, tmp_path):
    out, _ = learned_run
    p = run_app("zshape=learned_pair", f"zshape.file={out / 'learned_z.json'}", f"hydra.run.dir={tmp_path / 'r'}")
    assert p.returncode == 2 and "mode: the file holds 'learned' Z, zshape.kind is 'learned_pair'" in p.stderr
    p = run_app("zshape=learned_pair", "zshape.steps=1", f"hydra.run.dir={tmp_path / 'pair'}")
    assert p.returncode == 0, p.stderr
    table = load_z_table(tmp_path / "pair" / "learned_z.json")
    assert table.mode == "learned_pair" and table.n_shapes == 1 and len(table.pairs) > 0
    report = verify_directory(tmp_path / "pair", complete=True)
    assert report.ok, report.findings
    with np.load(tmp_path / "pair" / "transitions.npz") as z:
        assert sum(k.endswith("_Z") and k.startswith("edge_") for k in z.files) == report.n_edges


@pytest.mark.parametrize("overrides, message", [
    (["+zshape.steps=3"], "zshape.steps: applies to zshape=learned and zshape=learned_pair only"),
    (["zshape=learned", "zshape.learning_rate=0"], "zshape.learning_rate: expected a finite number in [1e-6, 10]"),
    (["zshape=learned", "zshape.steps=-1"], "zshape.steps: expected an integer in [0, 10000], got -1"),
    (["zshape=learned", "zshape.init=learned"], "zshape.init: expected one of best, box, diamond, cell, regular"),
    (["zshape=learned", "zshape.file=no/such/learned_z.json"], "zshape.file: file 'no/such/learned_z.json' not found"),
    (["zshape=learned", "zshape.horizon=first"], "zshape.horizon: expected one of last, best"),
    (["+zshape.horizon=best"], "zshape.horizon: applies to zshape=learned and zshape=learned_pair only"),
    (["zshape=learned", "zshape.steps=0", "zshape.init=box"], "zshape.init: 'box' does not fit the source cells with 3"),
])
def test_bad_values_are_refused_clearly(tmp_path, overrides, message):
    rooms = "init: 'box'" in message                         # triangles
    p = run_app(*overrides, f"hydra.run.dir={tmp_path / 'r'}",
                **({"workspace": "workspace=rooms"} if rooms else {}))
    assert p.returncode == 2 and message in p.stderr, p.stderr


def test_learning_is_deterministic_and_rebuilds(paper_system, tmp_path):
    decomp = parse_grid_map("...\n.#.")
    system = paper_system(0.2)
    opts = LearnOptions(steps=2, learning_rate=0.1, seed=3)
    shas = [learn_table(decomp, system, "learned_pair", options=opts._replace(L_max=4), progress=False)
            .save(tmp_path / f"z{k}.json") for k in range(2)]
    assert shas[0] == shas[1]
    table = load_z_table(tmp_path / "z0.json", sha256=shas[0])
    Z = assignment_from_table(decomp, table, "box", 2.0)
    (i, j), P = next(iter(sorted(table.pairs.items())))
    np.testing.assert_allclose(Z.of_pair(i, j).vertices, 2.0 * P.vertices)
    np.testing.assert_allclose(Z[0].vertices, 2.0 * table.z_for_cell(decomp.cells[0]).vertices)


def test_inputs_without_a_file_or_with_a_bad_one(tmp_path):
    system = {"name": "integrator2d", "A": [[1.0, 0.0], [0.0, 1.0]], "B": [[0.5, 0.0], [0.0, 0.5]],
              "U": {"kind": "box", "bound": 1.0}}
    base = {"workspace": {"kind": "grid", "map_file": str(TINY)}, "system": system,
            "disturbance": {"kind": "ball", "radius": 0.2}}
    inputs = ProblemInputs.from_dict({**base, "zshape": {"kind": "learned"}})
    with pytest.raises(InputError, match="zshape.file: zshape=learned needs a learned Z file"):
        inputs.build_cross_sections(inputs.build_decomposition())
    (tmp_path / "bad.json").write_text('{"format": "tubejax.learned_z", "version": 1, "mode": "learned"}')
    inputs = ProblemInputs.from_dict({**base, "zshape": {"kind": "learned", "file": str(tmp_path / "bad.json")}})
    with pytest.raises(InputError, match=r"bad.json: dim: missing"):
        inputs.build_cross_sections(inputs.build_decomposition())
    assert ProblemInputs.from_dict(base).record()["zshape"] == {"kind": "box", "scale": 1.0}


def test_learned_pair_shards_merge_and_verify(tmp_path):
    sweep = tmp_path / "sweep"
    for k in range(2):
        p = run_app("zshape=learned_pair", "zshape.steps=1", "shard.count=2", f"shard.index={k}",
                    f"hydra.run.dir={sweep / str(k)}")
        assert p.returncode == 0, p.stderr
    assert (sweep / "0" / "learned_z.json").read_bytes() == (sweep / "1" / "learned_z.json").read_bytes()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    p = subprocess.run([sys.executable, str(ROOT / "experiments" / "merge.py"), str(sweep)], cwd=ROOT,
                       capture_output=True, text=True, timeout=600, env=env)
    assert p.returncode == 0, p.stderr
    report = verify_directory(sweep / "merged", complete=True)
    assert report.ok, report.findings
    with np.load(sweep / "merged" / "transitions.npz") as z:
        assert sum(k.startswith("edge_") and k.endswith("_Z") for k in z.files) == report.n_edges > 0
