"""Plan over a transition system and simulate the closed loop (Algorithms 1 and 3).

Examples
--------
python experiments/simulate.py                                   # paper example, 50 uniform runs
python experiments/simulate.py spec.sequence=[1,2] sim.runs=1000 sim.disturbance=adversarial
python experiments/simulate.py 'spec.formula="F(l3 & F l5) & G(!l2)"' sim.disturbance=adversarial
python experiments/simulate.py spec.patrol=[3,5,6] spec.avoid=[4] sim.cycles=3
python experiments/simulate.py abstraction_dir=outputs/.../ workspace.map_file=...  # reuse an abstraction
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import (ConfigError, app_flags, check_config_files, config_dict, search_dirs,  # noqa: E402
                    sim_settings, spec_settings, write_json)

log = logging.getLogger("tubejax")
SUMMARY_KEYS = ("runs", "obstacle_entries", "tube_exits", "workspace_exits", "runs_reaching_all_targets")
#: Exit code of a simulation that saw an obstacle entry, a tube or workspace exit, or a missed target.
EXIT_VIOLATION = 1


def abstraction_dir(value) -> Path:
    """``abstraction_dir`` resolved: a directory holding transitions.json and transitions.npz."""
    p = Path(str(value)).expanduser()
    cands = [p] if p.is_absolute() else [d / p for d in search_dirs()]
    found = next((c for c in cands if c.exists()), None)
    if found is None:
        raise ConfigError(f"abstraction_dir: {str(value)!r} not found (looked in {', '.join(map(str, cands))})")
    if not found.is_dir():
        raise ConfigError(f"abstraction_dir: expected a directory holding transitions.json and transitions.npz, "
                          f"got the file {str(found)!r}")
    missing = [f for f in ("transitions.json", "transitions.npz") if not (found / f).is_file()]
    if missing:
        hint = (" (rounds/ is there: the run was interrupted before it wrote them; continue it with "
                f"experiments/abstract.py resume=true hydra.run.dir={found})"
                if (found / "rounds" / "manifest.json").exists() else "")
        raise ConfigError(f"abstraction_dir: {str(found)!r} holds no {' and no '.join(missing)}{hint}")
    return found


def get_abstraction(cfg: DictConfig, out: Path):
    """Load ``cfg.abstraction_dir`` or build the abstraction into ``out``."""
    from tubejax.transitions import TransitionSystem

    flags = app_flags(config_dict(cfg), simulate=True)
    if flags.abstraction_dir:
        d = abstraction_dir(flags.abstraction_dir)
        try:
            ts = TransitionSystem.load(d)               # strict; rebuilt from its sources and compared
        except (OSError, ValueError) as exc:            # TransitionFileError names the file and field
            why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ConfigError(f"abstraction_dir: cannot load the transition system: {why}") from None
        log.info("loaded %d cells, %d edges from %s", ts.n_cells, ts.n_edges, d)
        return ts
    from abstract import run_abstraction

    ts, jpath, _ = run_abstraction(cfg, out)
    log.info("abstraction: %d cells, %d edges -> %s", ts.n_cells, ts.n_edges, jpath)
    return ts


def make_plan(cfg: DictConfig, ts):
    """The plan for ``cfg.spec`` (start in the first label's region, or at ``spec.start_cell``)."""
    from tubejax.control import plan_sequence

    spec = spec_settings(config_dict(cfg).get("spec"))
    seq = spec.labels
    start = spec.start_cell
    if start is None:
        cells = ts.decomposition.cells_with_label(seq[0])
        if not cells:
            raise ConfigError(f"spec.sequence: no cell carries the start label {seq[0]!r}")
        start = cells[0]
    elif start >= ts.n_cells:
        raise ConfigError(f"spec.start_cell: expected a cell id in [0, {ts.n_cells - 1}], got {start}")
    return plan_sequence(ts, int(start), seq[1:], method=spec.planner)


def make_spec_plan(cfg: DictConfig, ts):
    """The :class:`tubejax.spec.SpecPlan` for ``cfg.spec``: ``formula`` (LTLf, sound product),
    ``patrol`` (cycles ``sim.cycles``, avoiding ``spec.avoid``) or ``sequence`` (the plan of
    :func:`make_plan`, monitored against its sequence automaton; with ``spec.planner=product``
    the sequence goes through the sound product instead).

    Formula and patrol plans start in ``spec.start_cell``, else in the first cell of ``spec.sequence[0]``.
    """
    from tubejax.spec import plan_formula, plan_patrol, plan_sequence_spec, sequence_spec_plan

    c = config_dict(cfg)
    spec = spec_settings(c.get("spec"))
    sim = c.get("sim") or {}
    start = spec.start_cell
    if start is None:
        cells = ts.decomposition.cells_with_label(spec.labels[0])
        if not cells:
            raise ConfigError(f"spec.sequence: no cell carries the start label {spec.labels[0]!r} "
                              "(formula and patrol plans start there too, unless spec.start_cell is given)")
        start = cells[0]
    elif start >= ts.n_cells:
        raise ConfigError(f"spec.start_cell: expected a cell id in [0, {ts.n_cells - 1}], got {start}")
    if spec.formula is not None:
        return plan_formula(ts, int(start), spec.formula)
    if spec.patrol is not None:
        cycles = sim_settings(sim.get("runs"), sim.get("disturbance"), sim.get("seed"), cycles=sim.get("cycles", 1)).cycles
        return plan_patrol(ts, int(start), [str(x) for x in spec.patrol], cycles=cycles,
                           avoid=[str(x) for x in spec.avoid])
    if spec.planner == "product":                      # the sequence through the sound product
        return plan_sequence_spec(ts, int(start), spec.labels[1:])
    return sequence_spec_plan(ts, make_plan(cfg, ts))


def check_plan_edges(ts, plan) -> None:
    """Re-check the evidence of the edges a plan uses (float64, margin, exact proof where claimed)."""
    from tubejax.verify import check_edges

    bad = check_edges(ts, plan.edges)
    if bad:
        more = f" (and {len(bad) - 1} more; run python -m tubejax verify)" if len(bad) > 1 else ""
        raise ConfigError(f"abstraction: {bad[0]}{more}")


def run_spec_simulation(ts, spec_plan, runs, mode, seed, progress: bool = False):
    """Simulate and monitor ``runs`` runs of ``spec_plan``; returns the result and its summary dict
    (``progress``: a bar over the runs on stderr)."""
    from tubejax.spec import simulate_spec

    s = sim_settings(runs, mode, seed)
    res = simulate_spec(ts, spec_plan, n_runs=s.runs, mode=s.mode, seed=s.seed, progress=progress)
    return res, res.summary()


def run_simulation(ts, plan, runs, mode, seed, field: str = "sim", progress: bool = False):
    """Simulate ``runs`` closed-loop runs along ``plan``; returns the result and its summary dict.

    ``runs``, ``mode`` and ``seed`` are validated (:class:`tubejax.inputs.SimulationSettings`);
    errors name ``{field}.runs``, ``{field}.disturbance`` or ``{field}.seed``. ``progress``: a bar
    over the runs on stderr.
    """
    from tubejax.control import simulate

    s = sim_settings(runs, mode, seed, field)
    res = simulate(ts, plan, n_runs=s.runs, mode=s.mode, seed=s.seed, progress=progress)
    return res, res.summary()


def figure_edge(ts, plan, edge=None) -> int:
    """The index of the edge drawn as Fig. 6.

    ``edge`` (``figures.edge``): ``[i, j]``, the transition from cell ``i`` to cell ``j``; ``None``:
    region 1 -> region 2 as in the paper when that edge exists, else the plan's first edge.

    Raises
    ------
    ConfigError
        ``figures.edge`` names no transition of ``ts``.
    """
    idx = ts.edge_index()
    if edge is not None:
        i, j = (int(v) for v in edge)
        if (i, j) not in idx:
            why = (f"cell ids are 0 .. {ts.n_cells - 1}" if max(i, j) >= ts.n_cells
                   else f"the abstraction has no transition {i} -> {j}")
            raise ConfigError(f"figures.edge: expected a transition [i, j] of the abstraction ({why}), got [{i}, {j}]")
        return idx[i, j]
    d = ts.decomposition
    for i in d.cells_with_label("1"):
        for j in d.cells_with_label("2"):
            if (i, j) in idx:
                return idx[i, j]
    return plan.edges[0]


def write_figures(ts, plan, result, out: Path, settings=None) -> list:
    """Figs. 5-7 and the transition graph, PNG + PDF, into ``out``.

    ``settings`` (:class:`tubejax.inputs.FigureSettings`, the ``figures`` section; default: its
    defaults) gives the size, the PNGs' dpi, Fig. 6's edge and how many runs Fig. 7 draws.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tubejax.inputs import FigureSettings
    from tubejax.plot import (new_axes, plot_transition_graph, plot_trajectories, plot_tube,
                              plot_workspace, save_figure)

    fs = FigureSettings() if settings is None else settings
    edge = figure_edge(ts, plan, fs.edge)
    files = []
    for stem, draw in [("fig5_workspace", lambda ax: plot_workspace(ts.decomposition, ax)),
                       ("fig6_tube", lambda ax: plot_tube(ts, edge, ax)),
                       ("fig7_trajectories", lambda ax: plot_trajectories(ts.decomposition, result, ax,
                                                                          max_runs=fs.runs_drawn,
                                                                          density=fs.density)),
                       ("transition_graph", lambda ax: plot_transition_graph(ts, ax))]:
        fig, ax = new_axes((fs.width, fs.height))
        draw(ax)
        files += [str(p) for p in save_figure(fig, out, stem, dpi=fs.dpi)]
        plt.close(fig)
    return files


def write_spec_figure(ts, spec_plan, sim, out: Path, settings=None) -> list:
    """``fig8_specification``: runs over the map, avoided regions shaded, the plan (PNG + PDF);
    ``settings`` as in :func:`write_figures` (the figure is 10 % taller, for its legend)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tubejax.inputs import FigureSettings
    from tubejax.plot import new_axes, plot_specification, save_figure

    fs = FigureSettings() if settings is None else settings
    fig, ax = new_axes((fs.width, 1.1 * fs.height))
    plot_specification(ts, spec_plan, sim, ax, max_runs=fs.runs_drawn, density=fs.density)
    files = [str(p) for p in save_figure(fig, out, "fig8_specification", dpi=fs.dpi)]
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
        c = config_dict(cfg)
        flags = app_flags(c, simulate=True)
        spec_settings(c.get("spec"))                               # refuse bad values before any work
        sim = c.get("sim") or {}
        sim_settings(sim.get("runs"), sim.get("disturbance"), sim.get("seed"), cycles=sim.get("cycles", 1))
        ts = get_abstraction(cfg, out)
        spec_plan = make_spec_plan(cfg, ts)
        plan = spec_plan.plan
        check_plan_edges(ts, plan)
        if flags.figures.enabled:
            figure_edge(ts, plan, flags.figures.edge)              # a bad figures.edge: refused before simulating
        res, summary = run_spec_simulation(ts, spec_plan, sim.get("runs"), sim.get("disturbance"), sim.get("seed"),
                                           progress=flags.progress)
    except ValueError as exc:                  # ConfigError, PlanningError, SpecificationError, ...
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    summary["plan_cells"] = list(map(int, plan.cells))
    summary["plan_steps"] = int(plan.cost)
    summary["plan_stats"] = {k: v for k, v in spec_plan.stats.items() if k != "seconds"}
    summary["disturbance_mode"] = str(cfg.sim.disturbance)
    write_json(out / "simulation.json", summary)
    files = (write_figures(ts, plan, res.result, out, flags.figures)
             + write_spec_figure(ts, spec_plan, res, out, flags.figures) if flags.figures.enabled else [])
    print(f"plan           : cells {plan.cells} ({plan.cost} steps)")
    print_summary(f"simulation ({cfg.sim.disturbance})", summary)
    print(f"wrote          : {out / 'simulation.json'}" + (f" and {len(files)} figure files" if files else ""))
    exit_on_violations(summary)


if __name__ == "__main__":
    check_config_files()
    main()
