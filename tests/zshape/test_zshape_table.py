"""The learned-Z file: round trip, checks with named fields, the make_z hook, a saved run that reloads."""

import json

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.zshape.kinds import make_z
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.transitions.transition_system import TransitionSystem
from tubejax.model.workspace.gridmap import parse_grid_map
from tubejax.model.zshape.z_table import ZTable, ZTableError, active_z_table, file_sha256, load_z_table, use_z_table

SQUARE = Polytope.box([0.0, 0.0], [1.0, 1.0])
KITE = [[-1.0, -1.0], [1.05, -0.98], [0.97, 1.02], [-1.02, 0.97]]
PAPER = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))


def table(z=KITE, pairs=None):
    return ZTable("learned", 2, [(SQUARE.vertices, z)], pairs, {"seed": 0})


def test_round_trip_is_bitwise_and_hashed(tmp_path):
    z = np.array(KITE) + 1e-13 * np.arange(8).reshape(4, 2)          # digits json must keep
    t = ZTable("learned_pair", 2, [(SQUARE.vertices, z)], {(0, 1): z, (3, 2): KITE}, {"note": "x"})
    sha = t.save(tmp_path / "learned_z.json")
    assert sha == file_sha256(tmp_path / "learned_z.json")
    back = load_z_table(tmp_path / "learned_z.json", sha256=sha)
    np.testing.assert_array_equal(back.z_for_cell(Polytope.box([5.0, 2.0], [6.0, 3.0])).vertices, z)
    np.testing.assert_array_equal(back.z_for_pair(0, 1).vertices, z)
    assert sorted(back.pairs) == [(0, 1), (3, 2)] and back.learning == {"note": "x"}
    with pytest.raises(ZTableError, match="SHA-256"):
        load_z_table(tmp_path / "learned_z.json", sha256="0" * 64)


@pytest.mark.parametrize("edit, field", [
    (lambda d: d.update(format="other"), "format"),
    (lambda d: d.update(version=2), "version"),
    (lambda d: d.pop("mode"), "mode: missing"),
    (lambda d: d.update(mode="box"), "mode"),
    (lambda d: d["shapes"][0].update(vertices=[[0, 0], [1, 0], [1, 1]]), r"shapes\[0\].vertices"),
    (lambda d: d["shapes"][0].update(vertices=[[-1, -1], [1, -1], [-1, 1], [1, 1]]), r"shapes\[0\].vertices"),
    (lambda d: d["shapes"][0].update(vertices=[[-1, -0.5], [1, -1], [1, 1], [-1, 1]]), r"shapes\[0\].vertices"),
    (lambda d: d["shapes"][0].update(vertices=[[1, 1], [2, 1], [2, 2], [1, 2]]), "invariant"),   # 0 outside
    (lambda d: d["shapes"][0].update(cell=[[0, 0], [1, 0]]), r"shapes\[0\].cell"),
    (lambda d: d["pairs"].append({"from": 0, "to": 0, "vertices": KITE}), "distinct"),
    (lambda d: d["pairs"].append({"from": 0, "to": "1", "vertices": KITE}), "integers"),
    (lambda d: d["pairs"].extend([{"from": 0, "to": 1, "vertices": KITE}] * 2), "second Z"),
])
def test_bad_files_name_the_field(tmp_path, edit, field):
    doc = table().to_json()
    edit(doc)
    p = tmp_path / "learned_z.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(ZTableError, match=field) as exc:
        load_z_table(p)
    assert str(p) in str(exc.value)


def test_unreadable_and_non_json(tmp_path):
    with pytest.raises(ZTableError, match="cannot read"):
        load_z_table(tmp_path / "missing.json")
    (tmp_path / "nan.json").write_text('{"format": "tubejax.learned_z", "version": 1, "x": NaN}')
    with pytest.raises(ZTableError, match="not valid JSON"):
        load_z_table(tmp_path / "nan.json")


def test_make_z_hook():
    with pytest.raises(ValueError, match="needs a learned Z table"):
        make_z("learned", SQUARE)
    with pytest.raises(ValueError, match="per ordered pair"):
        make_z("learned_pair", SQUARE)
    t = table()
    np.testing.assert_array_equal(make_z("learned", SQUARE, table=t).vertices, KITE)
    with use_z_table(t):
        assert active_z_table() is t
        np.testing.assert_allclose(make_z("learned", SQUARE, 2.0).vertices, 2 * np.array(KITE))
        with pytest.raises(ValueError, match="no learned Z for a cell of shape"):
            make_z("learned", Polytope.box([0.0, 0.0], [2.0, 1.0]))
    assert active_z_table() is None


def test_learned_z_run_saves_reloads_and_verifies(tmp_path):
    """A run with a learned Z saves, reloads with the same Z (same pairing) and re-verifies every edge."""
    decomp = parse_grid_map("..\n..")
    with use_z_table(table()):
        ts = build_abstraction(decomp, PAPER, zshape="learned", L_max=6, progress=False)
    assert ts.stats["zshape"] == "learned" and ts.n_edges > 0
    for Z in ts.Z:
        np.testing.assert_array_equal(Z.vertices, KITE)
    ts.save(tmp_path)
    sha = table().save(tmp_path / "learned_z.json")              # what verify would rebuild Z from
    again = load_z_table(tmp_path / "learned_z.json", sha256=sha)
    for i, c in enumerate(decomp.cells):
        np.testing.assert_array_equal(make_z("learned", c, 1.0, table=again).vertices, ts.Z[i].vertices)
    back = TransitionSystem.load(tmp_path)
    for Z in back.Z:                                             # the pairing survives the reload
        np.testing.assert_array_equal(Z.vertices, KITE)
    assert [(e.src, e.dst, e.L) for e in back.edges] == [(e.src, e.dst, e.L) for e in ts.edges]
    assert np.all(back.verify() <= 1e-9)
    assert all(e.proof == "exact" for e in back.edges)
