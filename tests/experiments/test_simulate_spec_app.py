"""experiments/simulate.py with spec.formula and spec.patrol, run as a user would."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
AVOID_MAP = "1.4.2\n.###.\n3....\n"


def run(*overrides, timeout=900):
    return subprocess.run([sys.executable, str(ROOT / "experiments" / "simulate.py"), "progress=false", *overrides],
                          cwd=ROOT, capture_output=True, text=True, timeout=timeout)


def test_formula_and_patrol(tmp_path):
    m = tmp_path / "avoid.txt"
    m.write_text(AVOID_MAP)
    out = tmp_path / "formula"
    p = run(f"workspace.map_file={m}", "solver=highs", 'spec.formula="F(l3 & F(l2)) & G(!l4)"',
            "sim.runs=500", "sim.disturbance=adversarial", f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads((out / "simulation.json").read_text())
    assert s["runs"] == 500 and s["runs_satisfying_spec"] == 500 and s["avoided_region_entries"] == 0
    assert s["obstacle_entries"] == 0 and s["tube_exits"] == 0 and s["avoided_labels"] == ["4"]
    assert s["spec_kind"] == "formula" and s["plan_steps"] == s["steps"] > 0
    assert (out / "fig8_specification.png").stat().st_size > 5000 and (out / "fig8_specification.pdf").exists()
    assert "500 of 500 runs satisfy it" in p.stdout
    # reuse the abstraction: patrol 3 -> 2 twice, never near 4
    p = run(f"abstraction_dir={out}", "spec.patrol=[3,2]", "spec.avoid=[4]", "sim.cycles=2", "sim.runs=100",
            "figures=false", f"hydra.run.dir={tmp_path / 'patrol'}")
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads((tmp_path / "patrol" / "simulation.json").read_text())
    assert s["spec_kind"] == "patrol" and s["plan_stats"]["cycles"] == 2
    assert s["runs_satisfying_spec"] == 100 and s["avoided_region_entries"] == 0
    # LTL over infinite runs: the cheapest lasso, its cycle twice, every run's words checked by Spot
    p = run(f"abstraction_dir={out}", 'spec.ltl="GF l3 & GF l2 & G !l4"', "spec.start_cell=0", "sim.cycles=2",
            "sim.runs=200", "sim.disturbance=adversarial", f"hydra.run.dir={tmp_path / 'ltl'}")
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads((tmp_path / "ltl" / "simulation.json").read_text())
    assert s["spec_kind"] == "ltl" and s["runs_satisfying_spec"] == 200 and s["avoided_region_entries"] == 0
    lasso = s["lasso"]
    assert lasso["cycle"][0] == lasso["cycle"][-1] == lasso["prefix"][-1] and lasso["cycles"] == 2
    assert s["plan_cells"] == lasso["prefix"] + lasso["cycle"][1:] * 2
    assert s["plan_steps"] == lasso["prefix_steps"] + 2 * lasso["cycle_steps"] and "lasso          : prefix" in p.stdout
    assert (tmp_path / "ltl" / "fig8_specification.png").exists()
    p = run(f"abstraction_dir={out}", 'spec.ltl="GF l3 & last"', "figures=false", f"hydra.run.dir={tmp_path / 'e2'}")
    assert p.returncode == 2 and "give this formula as spec.formula" in p.stderr and "Traceback" not in p.stderr
    # a bad formula: exit 2 with the position, no traceback
    p = run(f"abstraction_dir={out}", 'spec.formula="F(l2 & G(!l4)"', "figures=false", f"hydra.run.dir={tmp_path / 'err'}")
    assert p.returncode == 2 and "syntax error at position 13" in p.stderr and "Traceback" not in p.stderr
    # the other refusals, in process (same code path, no interpreter start-up)
    from omegaconf import OmegaConf

    from tubejax.transitions.transition_system import TransitionSystem
    sys.path.insert(0, str(ROOT / "experiments"))
    from simulate import make_spec_plan

    ts = TransitionSystem.load(out)
    base = {"sequence": [1, 2], "start": None, "start_cell": None, "planner": "exact", "formula": None, "ltl": None, "patrol": None,
            "avoid": []}
    for spec, msg in [({"formula": "F(l2) & G(!l4) & G(!l3) & G(!l1)"}, "already violated at the start cell"),
                      ({"formula": "F(l7)"}, "unknown propositions l7 (position 2)"),
                      ({"formula": "F(l2) & G(!l4) & F(l3) & G(!l1)"}, "already violated"),
                      ({"patrol": [3], "formula": "F(l2)"}, "not both"),
                      ({"ltl": "GF l2 & G !l1"}, "the start cell 0 already violates it"),
                      ({"ltl": "GF l7"}, "unknown propositions l7 (position 3)"),
                      ({"avoid": [4]}, "spec.avoid: applies to spec.patrol"),
                      ({"formula": 3}, "spec.formula: expected an LTLf formula as a string"),
                      ({"sequence": [9, 2], "formula": "F(l2)"}, "spec.sequence: no cell carries the start label '9' "
                                                                 "(the map's labels: 1, 2, 3, 4); start elsewhere with "
                                                                 "spec.start=LABEL"),
                      ({"start": 9, "formula": "F(l2)"}, "spec.start: no cell carries the start label '9'"),
                      ({"start": 3, "start_cell": 0, "formula": "F(l2)"}, "spec.start: give spec.start"),
                      ({"sequence": [3]}, "spec.sequence: [3] names a start and no region to visit"),
                      ({"start": 3}, "spec.start: a sequence starts in its first region (1)")]:
        sim = {"cycles": 2, "runs": 10, "disturbance": "uniform", "seed": 0}
        cfg = OmegaConf.create({"spec": {**base, **spec}, "sim": sim})
        with pytest.raises(ValueError, match=re.escape(msg)):
            make_spec_plan(cfg, ts)
    cfg = OmegaConf.create({"spec": {**base, "sequence": [1, 3, 2], "planner": "product"}, "sim": {}})
    sp = make_spec_plan(cfg, ts)
    assert sp.kind == "sequence" and sp.plan.method == "product"
    assert sp.cost <= make_spec_plan(OmegaConf.create({"spec": {**base, "sequence": [1, 3, 2]}}), ts).cost
    cfg = OmegaConf.create({"spec": {**base, "patrol": [3, 2]}, "sim": {"cycles": 0}})
    with pytest.raises(ValueError, match="sim.cycles"):
        make_spec_plan(cfg, ts)


LETTER_MAP = "A...\n.##.\n...B\nC...\n"


def test_a_formula_starts_in_a_region_named_on_the_command_line(tmp_path):
    """``spec.start=A`` on a map without region 1 (the default sequence's start): the formula's plan
    starts in A's cell; a one-label sequence is the same start; without either the message says how."""
    m = tmp_path / "letters.txt"
    m.write_text(LETTER_MAP)
    common = [f"workspace.map_file={m}", "solver=highs", "L_max=4", "sim.runs=20", "figures=false",
              'spec.formula="F(lB) & G(!lC)"']
    p = run(*common, "spec.start=A", f"hydra.run.dir={tmp_path / 'a'}")
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads((tmp_path / "a" / "simulation.json").read_text())
    assert s["plan_cells"][0] == 0 and s["runs_satisfying_spec"] == 20 and s["avoided_labels"] == ["C"]
    assert "plan           : F(lB) & G(!lC) through cells [0, " in p.stdout
    p = run(f"abstraction_dir={tmp_path / 'a'}", *common[3:], "spec.sequence=[A]", f"hydra.run.dir={tmp_path / 'b'}")
    assert p.returncode == 0, p.stderr[-3000:]
    assert json.loads((tmp_path / "b" / "simulation.json").read_text())["plan_cells"] == s["plan_cells"]
    p = run(f"abstraction_dir={tmp_path / 'a'}", *common[3:], f"hydra.run.dir={tmp_path / 'c'}")
    assert p.returncode == 2 and "Traceback" not in p.stderr
    assert ("error: spec.sequence: no cell carries the start label '1' (the map's labels: A, B, C); start elsewhere "
            "with spec.start=LABEL or spec.start_cell=ID") in p.stderr


def test_spec_violations_exit_nonzero():
    from tubejax.analyses.control.simulate import summary_violations as violations

    ok = {"runs": 10, "obstacle_entries": 0, "tube_exits": 0, "workspace_exits": 0,
          "runs_reaching_all_targets": 10, "runs_satisfying_spec": 10, "avoided_region_entries": 0}
    assert violations(ok) == []
    assert violations({**ok, "runs_satisfying_spec": 9}) == ["1 runs violating the specification"]
    assert violations({**ok, "avoided_region_entries": 2}) == ["2 runs entering an avoided region"]
