"""The paper's example end to end (Section V), from one command.

1. the abstraction (Algorithm 2) on the paper map, r = 0.2, L_max = 10;
2. the plan 1 -> 3 -> 4 -> 5 -> 6 (Dijkstra, cost L);
3. 50 runs from random initial states in region 1 with random disturbances in W;
4. 10,000 further runs under adversarial disturbances (docs/math/control.md);
5. Figs. 5-7 and the transition graph (the ``figures`` section of conf/simulate.yaml; ``figures=false``:
   none), and a printed summary.
"""

from __future__ import annotations

import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))
from abstract import count_lines  # noqa: E402
from common import app_flags, check_config_files, config_dict, spec_settings, write_json  # noqa: E402
from simulate import (SUMMARY_KEYS, exit_on_violations, figure_edge, make_plan, print_summary,  # noqa: E402
                      run_simulation, write_figures)
from simulated_abstraction import get_abstraction  # noqa: E402


@hydra.main(version_base=None, config_path="../conf", config_name="paper")
def main(cfg: DictConfig) -> None:
    out = Path(hydra.core.hydra_config.HydraConfig.get().runtime.output_dir)
    try:
        flags = app_flags(config_dict(cfg), simulate=True)         # progress, figures, ...: refused before any work
        ts = get_abstraction(cfg, out)
        plan = make_plan(cfg, ts)
        if flags.figures.enabled:
            figure_edge(ts, plan, flags.figures.edge)
        res, paper_runs = run_simulation(ts, plan, cfg.sim.runs, cfg.sim.disturbance, cfg.sim.seed,
                                         progress=flags.progress)
        _, adversarial = run_simulation(ts, plan, cfg.adversarial_runs, "adversarial", cfg.sim.seed + 1,
                                        progress=flags.progress)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    total = {k: paper_runs[k] + adversarial[k] for k in SUMMARY_KEYS}
    write_json(out / "simulation.json", {**total, "paper_runs": paper_runs, "adversarial_runs": adversarial,
                                         "plan_cells": list(map(int, plan.cells)), "plan_steps": int(plan.cost)})
    files = write_figures(ts, plan, res, out, flags.figures) if flags.figures.enabled else []
    s = ts.stats
    print("\n".join(count_lines(ts)))
    n_tr = s.get("n_translated", 0)
    print(f"abstraction    : {s['n_lps'] - n_tr} LPs solved (+{n_tr} settled by translation) in {s['seconds']:.1f} s, "
          f"solver {s.get('solver')}")
    print(f"plan           : {' -> '.join(spec_settings(config_dict(cfg).get('spec')).labels)} through cells "
          f"{plan.cells} ({plan.cost} steps)")
    print_summary(f"§V experiment ({cfg.sim.disturbance})", paper_runs)
    print_summary("adversarial", adversarial)
    print_summary("all", total)
    print(f"wrote          : {out}/ transitions.json, transitions.npz, metrics.json, simulation.json"
          + (f", {len(files)} figure files" if files else ""))
    exit_on_violations(total)


if __name__ == "__main__":
    check_config_files()
    main()
