"""Plan over a transition system and simulate the closed loop (Algorithms 1 and 3).

Examples
--------
python experiments/simulate.py                                   # paper example, 50 uniform runs
python experiments/simulate.py spec.sequence=[1,2] sim.runs=1000 sim.disturbance=adversarial
python experiments/simulate.py abstraction_dir=outputs/.../ workspace.map_file=...  # reuse an abstraction
python experiments/simulate.py 'spec.formula="F(l3 & F l5) & G(!l2)"' sim.disturbance=adversarial
python experiments/simulate.py spec.patrol=[3,5,6] spec.avoid=[4] sim.cycles=3
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import ConfigError, resolve_path, write_json  # noqa: E402

log = logging.getLogger("tubejax")
SUMMARY_KEYS = ("runs", "obstacle_entries", "tube_exits", "workspace_exits", "runs_reaching_all_targets")
#: Exit code of a simulation that saw an obstacle entry, a tube or workspace exit, or a missed target.
EXIT_VIOLATION = 1


def get_abstraction(cfg: DictConfig, out: Path):
    """Load ``cfg.abstraction_dir`` or build the abstraction into ``out``."""
    from tubejax.transitions import TransitionSystem

    if cfg.get("abstraction_dir"):
        d = resolve_path(cfg.abstraction_dir, "abstraction_dir")
        ts = TransitionSystem.load(d)
        log.info("loaded %d cells, %d edges from %s", ts.n_cells, ts.n_edges, d)
        return ts
    from abstract import run_abstraction

    ts, jpath, _ = run_abstraction(cfg, out)
    log.info("abstraction: %d cells, %d edges -> %s", ts.n_cells, ts.n_edges, jpath)
    return ts


def make_plan(cfg: DictConfig, ts):
    """The plan for ``cfg.spec`` (start in the first label's region)."""
    from tubejax.control import plan_sequence

    seq = [str(s) for s in cfg.spec.sequence]
    if len(seq) < 2:
        raise ConfigError(f"spec.sequence: expected at least two region labels, got {list(cfg.spec.sequence)}")
    start = cfg.spec.start_cell
    if start is None:
        cells = ts.decomposition.cells_with_label(seq[0])
        if not cells:
            raise ConfigError(f"spec.sequence: no cell carries the start label {seq[0]!r}")
        start = cells[0]
    return plan_sequence(ts, int(start), seq[1:], method=str(cfg.spec.planner))


def make_spec_plan(cfg: DictConfig, ts):
    """The :class:`tubejax.spec.SpecPlan` for ``cfg.spec``: ``formula`` (LTLf, sound product),
    ``patrol`` (cycles ``cfg.sim.cycles``, avoiding ``spec.avoid``) or ``sequence`` (the
    plan of :func:`make_plan`, monitored against its sequence automaton; with
    ``spec.planner=product`` the sequence goes through the sound product instead).

    Formula and patrol plans start in ``spec.start_cell``, else in the first cell of ``spec.sequence[0]``.
    """
    from tubejax.spec import plan_formula, plan_patrol, plan_sequence_spec, sequence_spec_plan

    formula, patrol = cfg.spec.get("formula"), cfg.spec.get("patrol")
    avoid = [str(a) for a in (cfg.spec.get("avoid") or [])]
    if formula and patrol:
        raise ConfigError("spec.formula and spec.patrol: give one of them, not both")
    if avoid and not patrol:
        raise ConfigError("spec.avoid applies to spec.patrol; in a formula write G(!l<label>)")
    if not formula and not patrol:
        if str(cfg.spec.planner) == "product":             # the sequence through the sound product
            seq = [str(s) for s in cfg.spec.sequence]
            if len(seq) < 2:
                raise ConfigError(f"spec.sequence: expected at least two region labels, got {seq}")
            cells = ts.decomposition.cells_with_label(seq[0])
            if cfg.spec.start_cell is None and not cells:
                raise ConfigError(f"spec.sequence: no cell carries the start label {seq[0]!r}")
            start = cells[0] if cfg.spec.start_cell is None else int(cfg.spec.start_cell)
            return plan_sequence_spec(ts, start, seq[1:])
        return sequence_spec_plan(ts, make_plan(cfg, ts))
    start = cfg.spec.start_cell
    if start is None:
        first = str(list(cfg.spec.sequence)[0]) if cfg.spec.sequence else None
        cells = ts.decomposition.cells_with_label(first) if first is not None else []
        if not cells:
            raise ConfigError(f"spec.start_cell: not given, and no cell carries spec.sequence[0] = {first!r}")
        start = cells[0]
    if formula:
        if not isinstance(formula, str):
            raise ConfigError(f"spec.formula: expected a string, got {formula!r} (quote it: "
                              "'spec.formula=\"F(l3) & G(!l4)\"')")
        return plan_formula(ts, int(start), formula)
    cycles = cfg.sim.get("cycles", 1)
    if not isinstance(cycles, int) or cycles < 1:
        raise ConfigError(f"sim.cycles: expected an integer >= 1, got {cycles!r}")
    return plan_patrol(ts, int(start), [str(l) for l in patrol], cycles=cycles, avoid=avoid)


def run_spec_simulation(ts, spec_plan, runs: int, mode: str, seed: int):
    """Simulate and monitor ``runs`` runs of ``spec_plan``; returns the result and its summary dict."""
    from tubejax.spec import simulate_spec

    if int(runs) < 1:
        raise ConfigError(f"sim.runs: expected an integer >= 1, got {runs}")
    res = simulate_spec(ts, spec_plan, n_runs=int(runs), mode=str(mode), seed=int(seed))
    return res, res.summary()


def run_simulation(ts, plan, runs: int, mode: str, seed: int):
    """Simulate ``runs`` closed-loop runs along ``plan``; returns the result and its summary dict."""
    from tubejax.control import simulate

    if int(runs) < 1:
        raise ConfigError(f"sim.runs: expected an integer >= 1, got {runs}")
    res = simulate(ts, plan, n_runs=int(runs), mode=str(mode), seed=int(seed))
    return res, res.summary()


def figure_edge(ts, plan) -> int:
    """The edge drawn as Fig. 6: region 1 -> region 2 as in the paper when it exists, else the plan's first."""
    idx = ts.edge_index()
    d = ts.decomposition
    for i in d.cells_with_label("1"):
        for j in d.cells_with_label("2"):
            if (i, j) in idx:
                return idx[i, j]
    return plan.edges[0]


def write_figures(ts, plan, result, out: Path) -> list:
    """Figs. 5-7 and the transition graph, PNG + PDF, into ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tubejax.plot import (new_axes, plot_transition_graph, plot_trajectories, plot_tube,
                              plot_workspace, save_figure)

    files = []
    for stem, draw in [("fig5_workspace", lambda ax: plot_workspace(ts.decomposition, ax)),
                       ("fig6_tube", lambda ax: plot_tube(ts, figure_edge(ts, plan), ax)),
                       ("fig7_trajectories", lambda ax: plot_trajectories(ts.decomposition, result, ax)),
                       ("transition_graph", lambda ax: plot_transition_graph(ts, ax))]:
        fig, ax = new_axes()
        draw(ax)
        files += [str(p) for p in save_figure(fig, out, stem)]
        plt.close(fig)
    return files


def write_spec_figure(ts, spec_plan, sim, out: Path) -> list:
    """``fig8_specification``: runs over the map, avoided regions shaded, the plan (PNG + PDF)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tubejax.plot import new_axes, plot_specification, save_figure

    fig, ax = new_axes((6, 6.6))
    plot_specification(ts, spec_plan, sim, ax)
    files = [str(p) for p in save_figure(fig, out, "fig8_specification")]
    plt.close(fig)
    return files


def print_summary(title: str, s: dict) -> None:
    print(f"{title}: runs {s['runs']}, obstacle entries {s['obstacle_entries']}, tube exits "
          f"{s['tube_exits']}, workspace exits {s['workspace_exits']}, reaching all targets "
          f"{s['runs_reaching_all_targets']} ({100.0 * s['runs_reaching_all_targets'] / max(s['runs'], 1):.1f} %)")
    if "runs_satisfying_spec" in s:
        print(f"specification  : {s['spec']}: {s['runs_satisfying_spec']} of {s['runs']} runs satisfy it "
              f"({100.0 * s['runs_satisfying_spec'] / max(s['runs'], 1):.1f} %), avoided-region entries "
              f"{s['avoided_region_entries']}")


def violations(s: dict) -> list[str]:
    """What a simulation summary shows going wrong (empty when every run was safe and reached every target)."""
    bad = [f"{s[k]} runs with {k.replace('_', ' ')}" for k in ("obstacle_entries", "tube_exits", "workspace_exits")
           if s[k]]
    if s["runs_reaching_all_targets"] != s["runs"]:
        bad.append(f"{s['runs'] - s['runs_reaching_all_targets']} runs missing a target")
    if s.get("avoided_region_entries"):
        bad.append(f"{s['avoided_region_entries']} runs entering an avoided region")
    if "runs_satisfying_spec" in s and s["runs_satisfying_spec"] != s["runs"]:
        bad.append(f"{s['runs'] - s['runs_satisfying_spec']} runs violating the specification")
    return bad


def exit_on_violations(s: dict) -> None:
    """Exit with :data:`EXIT_VIOLATION` and a message on stderr if ``violations(s)`` is not empty."""
    bad = violations(s)
    if bad:
        print("error: the closed loop violated its guarantee: " + "; ".join(bad), file=sys.stderr)
        sys.exit(EXIT_VIOLATION)


@hydra.main(version_base=None, config_path="../conf", config_name="simulate")
def main(cfg: DictConfig) -> None:
    out = Path(hydra.core.hydra_config.HydraConfig.get().runtime.output_dir)
    try:
        ts = get_abstraction(cfg, out)
        spec_plan = make_spec_plan(cfg, ts)
        plan = spec_plan.plan
        sim, summary = run_spec_simulation(ts, spec_plan, cfg.sim.runs, cfg.sim.disturbance, cfg.sim.seed)
    except ValueError as exc:                  # ConfigError, PlanningError, SpecificationError, ...
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    summary["plan_cells"] = list(map(int, plan.cells))
    summary["plan_steps"] = int(plan.cost)
    summary["plan_stats"] = {k: v for k, v in spec_plan.stats.items() if k != "seconds"}
    summary["disturbance_mode"] = str(cfg.sim.disturbance)
    write_json(out / "simulation.json", summary)
    files = write_figures(ts, plan, sim.result, out) + write_spec_figure(ts, spec_plan, sim, out) if cfg.figures else []
    print(f"plan           : cells {plan.cells} ({plan.cost} steps)")
    print_summary(f"simulation ({cfg.sim.disturbance})", summary)
    print(f"wrote          : {out / 'simulation.json'}" + (f" and {len(files)} figure files" if files else ""))
    exit_on_violations(summary)


if __name__ == "__main__":
    main()
