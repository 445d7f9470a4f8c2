"""Plan over a transition system and simulate the closed loop (Algorithms 1 and 3).

Examples
--------
python experiments/simulate.py                                   # paper example, 50 uniform runs
python experiments/simulate.py spec.sequence=[1,2] sim.runs=1000 sim.disturbance=adversarial
python experiments/simulate.py abstraction_dir=outputs/.../ workspace.map_file=...  # reuse an abstraction
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


def print_summary(title: str, s: dict) -> None:
    print(f"{title}: runs {s['runs']}, obstacle entries {s['obstacle_entries']}, tube exits "
          f"{s['tube_exits']}, workspace exits {s['workspace_exits']}, reaching all targets "
          f"{s['runs_reaching_all_targets']} ({100.0 * s['runs_reaching_all_targets'] / max(s['runs'], 1):.1f} %)")


def violations(s: dict) -> list[str]:
    """What a simulation summary shows going wrong (empty when every run was safe and reached every target)."""
    bad = [f"{s[k]} runs with {k.replace('_', ' ')}" for k in ("obstacle_entries", "tube_exits", "workspace_exits")
           if s[k]]
    if s["runs_reaching_all_targets"] != s["runs"]:
        bad.append(f"{s['runs'] - s['runs_reaching_all_targets']} runs missing a target")
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
        plan = make_plan(cfg, ts)
        res, summary = run_simulation(ts, plan, cfg.sim.runs, cfg.sim.disturbance, cfg.sim.seed)
    except ValueError as exc:                  # ConfigError, PlanningError, GridMapError, ...
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    summary["plan_cells"] = list(map(int, plan.cells))
    summary["plan_steps"] = int(plan.cost)
    summary["disturbance_mode"] = str(cfg.sim.disturbance)
    write_json(out / "simulation.json", summary)
    files = write_figures(ts, plan, res, out) if cfg.figures else []
    print(f"plan           : cells {plan.cells} ({plan.cost} steps)")
    print_summary(f"simulation ({cfg.sim.disturbance})", summary)
    print(f"wrote          : {out / 'simulation.json'}" + (f" and {len(files)} figure files" if files else ""))
    exit_on_violations(summary)


if __name__ == "__main__":
    main()
