"""``init='best'`` (the app's default start), ``patience``, and the fallback ``Z`` of cells without a learned one."""

from pathlib import Path

import jax
import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.model.geometry import Ball
from tubejax.errors import InputError
from tubejax.inputs import ProblemInputs
from tubejax.inputs.settings import ZShapeSettings
from tubejax.model.system import LinearSystem, one_norm_input_set
from tubejax.model.workspace.gridmap import load_grid_map, parse_grid_map
from tubejax.model.workspace.polygon import parse_polygon_workspace_text
from tubejax.analyses.zshape import LearnOptions, learn_z
from tubejax.analyses.zshape.learn_run import learn_table
from tubejax.model.zshape.kinds import fallback_kind, start_kinds
from tubejax.model.zshape.z_table import assignment_from_table

jax.config.update("jax_enable_x64", True)

TINY = Path(__file__).resolve().parents[1] / "data" / "tiny.txt"
L1 = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2), W=Ball(2, 0.2))
TRIANGLES = "boundary: [[0, 0], [3, 0], [3, 2], [0, 2]]\nobstacles: []\nmax_area: 0.8\n"


def test_start_kinds_and_fallback():
    square = parse_grid_map("..").cells[0]
    triangle = parse_polygon_workspace_text(TRIANGLES).cells[0]
    assert start_kinds("best", square) == ["box", "cell", "diamond", "regular", "chamfer"]
    assert start_kinds("best", triangle) == ["cell", "regular", "chamfer"]
    assert start_kinds("cell", triangle) == ["cell"]
    with pytest.raises(ValueError, match="zshape.init: 'box' does not fit the source cells with 3"):
        start_kinds("box", triangle)
    assert fallback_kind("best", square) == "box" and fallback_kind("best", triangle) == "cell"
    assert fallback_kind("diamond", square) == "diamond"


def test_best_start_is_the_best_fixed_kind_and_learning_keeps_it(corridor_path):
    """On the 1-norm corridor diamond certifies nothing, box 44 and chamfer (8 vertices) all 70 of
    exact2d; 'best' learns each vertex count as its own family, each shape keeps the run that
    certifies most, and the learned Z certifies at least as many transitions as the best fixed one."""
    decomp = load_grid_map(corridor_path)
    fixed = {k: build_abstraction(decomp, L1, zshape=k, progress=False).n_edges for k in ("box", "diamond", "chamfer")}
    table = learn_table(decomp, L1, "learned", init="best", progress=False,
                        options=LearnOptions(steps=2, learning_rate=0.05, patience=1))
    assert table.learning["init"] == "best" and table.learning["patience"] == 1
    runs = table.learning["families"]
    assert [r["starts"] for r in runs] == [["box", "cell", "diamond", "regular"], ["chamfer"]]
    assert [r["n_vertices"] for r in runs] == [4, 8] and [r["shapes_taken"] for r in runs] == [0, 1]
    Z = assignment_from_table(decomp, table, "best")
    assert Z[0].n_vertices == 8
    ts = build_abstraction(decomp, L1, z=Z, zshape="learned", progress=False)
    assert ts.n_edges >= max(fixed.values()) == fixed["chamfer"] == 70 > fixed["box"] == 44 > fixed["diamond"]
    assert np.all(ts.verify() <= 1e-9)
    assert {e.proof for e in ts.edges} == {"exact"}


def test_patience_stops_early_and_is_checked():
    decomp = parse_grid_map("...\n...")
    opts = LearnOptions(steps=6, learning_rate=10.0)              # long steps: the best early, then no gain
    full = learn_z(decomp, L1, init="diamond", options=opts, progress=False)
    short = learn_z(decomp, L1, init="diamond", options=opts._replace(patience=2), progress=False)
    objective = [h["objective"] for h in full.history]
    best = int(np.argmax(objective))                              # the first best step
    assert best + 2 < 6 and max(objective[best + 1:]) < objective[best]
    # with patience 2 the group stops 2 steps after its best: the same history up to there
    assert len(full.history) == 7 and len(short.history) == best + 3
    assert [h["objective"] for h in short.history] == objective[:best + 3]
    np.testing.assert_array_equal(short.z, full.z)                # the same best iterate
    with pytest.raises(ValueError, match="patience"):
        learn_z(decomp, L1, options=LearnOptions(patience=0))


@pytest.mark.parametrize("zshape, message", [
    ({"kind": "learned", "init": "worst"}, "zshape.init: expected one of best, box, diamond, cell, regular"),
    ({"kind": "learned", "horizon": "first"}, "zshape.horizon: expected one of last, best"),
    ({"kind": "learned", "patience": 0}, "zshape.patience: expected an integer in [1, 10000]"),
    ({"kind": "box", "patience": 3}, "zshape.patience: applies to zshape=learned and zshape=learned_pair only"),
])
def test_settings_are_validated(zshape, message):
    base = {"workspace": {"kind": "grid", "map_file": str(TINY)},
            "system": {"A": [[1.0, 0.0], [0.0, 1.0]], "B": [[0.5, 0.0], [0.0, 0.5]], "U": {"kind": "box", "bound": 1.0}},
            "disturbance": {"kind": "ball", "radius": 0.2}}
    with pytest.raises(InputError) as err:
        ProblemInputs.from_dict({**base, "zshape": zshape})
    assert message in str(err.value)


def test_defaults_of_the_learned_kinds():
    s = ZShapeSettings.model_validate({"kind": "learned"})
    assert (s.init, s.steps, s.learning_rate, s.horizon, s.patience, s.seed) == ("best", 30, 0.05, "last", 5, 0)


def test_require_gain_keeps_the_start_without_a_strict_gain(corridor_path):
    """On the 1-norm corridor no step certifies more than the box: with require_gain the result is
    the box itself (without it, a tie with a larger surrogate may move Z)."""
    decomp = load_grid_map(corridor_path)
    opts = LearnOptions(steps=3, learning_rate=0.05, require_gain=True)
    res = learn_z(decomp, L1, init="box", options=opts, progress=False)
    np.testing.assert_array_equal(res.z, res.start_z)
    np.testing.assert_array_equal(res.margins, res.start_margins)
