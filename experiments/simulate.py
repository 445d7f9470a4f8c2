"""Plan over a transition system and simulate the closed loop (Algorithms 1 and 3).

Examples
--------
python experiments/simulate.py                                   # paper example, 50 uniform runs
python experiments/simulate.py spec.sequence=[1,2] sim.runs=1000 sim.disturbance=adversarial
python experiments/simulate.py 'spec.formula="F(l3 & F l5) & G(!l2)"' sim.disturbance=adversarial
python experiments/simulate.py 'spec.formula="F(lB) & G(!lC)"' spec.start=A   # start in region A
python experiments/simulate.py spec.patrol=[3,5,6] spec.avoid=[4] sim.cycles=3
python experiments/simulate.py 'spec.ltl="GF l3 & GF l6 & G !l4"' sim.cycles=3 sim.disturbance=adversarial
python experiments/simulate.py abstraction_dir=outputs/.../ sim.disturbance=boundary  # reuse an abstraction

With ``abstraction_dir`` the run is loaded as strictly as ``python -m tubejax verify`` reads it
(:func:`tubejax.verify.verifier.load_checked`: files, sources, copied data and every claim of the cheap
checks), the evidence of every edge the plan uses is re-checked, and an override of the problem
(``disturbance.radius=0.5``, ``workspace=corridor``) must equal the run's value: the loaded run
is what is simulated (``simulated_abstraction.py``: where the transition system comes from). Many
runs or long plans are simulated in chunks of bounded memory (:mod:`tubejax.analyses.control.chunks`);
a plan of which one run cannot fit is refused up front.
"""

from __future__ import annotations

import sys
from pathlib import Path

import hydra
import numpy as np
from omegaconf import DictConfig

from tubejax.analyses.control import SimulationRuns
from tubejax.analyses.control.chunks import SimulationTooLarge, chunk_runs, simulate_in_chunks
from tubejax.analyses.control.planner import cells_text
from tubejax.analyses.control.simulate import summary_violations

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import (ConfigError, app_flags, check_config_files, config_dict, sim_settings,  # noqa: E402
                    spec_settings, write_json)
from simulated_abstraction import get_abstraction  # noqa: E402

SUMMARY_KEYS = ("runs", "obstacle_entries", "tube_exits", "workspace_exits", "runs_reaching_all_targets")
#: After the count of the cells a long plan's line leaves out.
MORE = "; simulation.json lists them all"
#: Exit code of a simulation that saw an obstacle entry, a tube or workspace exit, or a missed target.
EXIT_VIOLATION = 1


def start_cell(ts, spec) -> int:
    """The cell a plan starts in: ``spec.start_cell``, else the first cell of the region ``spec.start``,
    else of ``spec.sequence[0]`` (a :class:`tubejax.inputs.SpecSettings`).

    Raises
    ------
    ConfigError
        The cell id is out of range, or no cell carries the label (the message lists the map's labels).
    """
    if spec.start_cell is not None:
        if spec.start_cell >= ts.n_cells:
            raise ConfigError(f"spec.start_cell: expected a cell id in [0, {ts.n_cells - 1}], got {spec.start_cell}")
        return int(spec.start_cell)
    label = spec.start_label
    cells = ts.decomposition.cells_with_label(label)
    if not cells:
        key = "spec.start" if spec.start is not None else "spec.sequence"
        have = sorted({str(x) for x in ts.decomposition.labels if x is not None}, key=lambda x: (len(x), x))
        raise ConfigError(f"{key}: no cell carries the start label {label!r} (the map's labels: "
                          f"{', '.join(have) or 'none'}); start elsewhere with spec.start=LABEL or spec.start_cell=ID")
    return int(cells[0])


def make_plan(cfg: DictConfig, ts):
    """The plan for ``cfg.spec`` (start in the first label's region, or at ``spec.start_cell``)."""
    from tubejax.analyses.control import plan_sequence

    spec = spec_settings(config_dict(cfg).get("spec"))
    return plan_sequence(ts, start_cell(ts, spec), spec.labels[1:], method=spec.planner)


def make_spec_plan(cfg: DictConfig, ts):
    """The :class:`tubejax.analyses.spec.SpecPlan` for ``cfg.spec``: ``formula`` (LTLf, sound product),
    ``ltl`` (the cheapest lasso, its cycle ``sim.cycles`` times), ``patrol`` (cycles ``sim.cycles``,
    avoiding ``spec.avoid``) or ``sequence`` (the plan of
    :func:`make_plan`, monitored against its sequence automaton; with ``spec.planner=product``
    the sequence goes through the sound product instead).

    Formula, ltl and patrol plans start in the region ``spec.start`` or the cell ``spec.start_cell``, else in
    the first cell of ``spec.sequence[0]`` (:func:`start_cell`).
    """
    from tubejax.analyses.spec import plan_formula, plan_ltl, plan_patrol, plan_sequence_spec, sequence_spec_plan

    c = config_dict(cfg)
    spec = spec_settings(c.get("spec"))
    sim = c.get("sim") or {}
    start = start_cell(ts, spec)
    if spec.formula is not None:
        return plan_formula(ts, int(start), spec.formula)
    if spec.ltl is not None or spec.patrol is not None:
        cycles = sim_settings(sim.get("runs"), sim.get("disturbance"), sim.get("seed"), cycles=sim.get("cycles", 1)).cycles
    if spec.ltl is not None:
        return plan_ltl(ts, int(start), spec.ltl, cycles=cycles)
    if spec.patrol is not None:
        return plan_patrol(ts, int(start), [str(x) for x in spec.patrol], cycles=cycles,
                           avoid=[str(x) for x in spec.avoid])
    if spec.planner == "product":                      # the sequence through the sound product
        return plan_sequence_spec(ts, int(start), spec.labels[1:])
    return sequence_spec_plan(ts, make_plan(cfg, ts))


def check_plan_edges(ts, plan) -> None:
    """Re-check the evidence of the edges a plan uses (float64, margin, exact proof where claimed)."""
    from tubejax.verify.verifier import check_edges

    bad = check_edges(ts, plan.edges)
    if bad:
        more = f" (and {len(bad) - 1} more; run python -m tubejax verify)" if len(bad) > 1 else ""
        raise ConfigError(f"abstraction: {bad[0]}{more}")


def _in_chunks(ts, plan, simulate_runs, s, key: str, progress: bool):
    """``s.runs`` runs of ``simulate_runs(SimulationRuns, progress)`` along ``plan``, in chunks of
    :func:`tubejax.analyses.control.chunks.chunk_runs` runs; a plan of which one run cannot fit in memory is
    refused naming ``key``."""
    try:
        per = chunk_runs(ts, plan, s.runs)
    except SimulationTooLarge as exc:
        raise ConfigError(f"{key}: {exc}") from None
    inner = progress if s.runs <= per else False      # one chunk: a bar over its runs; several: over them all

    def chunk(n, chunk_seed):
        res = simulate_runs(SimulationRuns(n_runs=n, mode=s.mode, seed=chunk_seed), inner)
        return res, res.summary()

    return simulate_in_chunks(chunk, s.runs, s.seed, per, progress)


def run_spec_simulation(ts, spec_plan, runs, mode, seed, progress: bool = False):
    """Simulate and monitor ``runs`` runs of ``spec_plan``; returns the result and its summary dict.

    Many runs or a long plan go in chunks of bounded memory (:mod:`tubejax.analyses.control.chunks`; the
    result is then the first chunk's, the summary all chunks'); with ``progress`` a bar shows them.
    """
    from tubejax.analyses.spec import simulate_spec

    key = "sim.cycles" if spec_plan.kind in ("patrol", "ltl") else "spec"
    return _in_chunks(ts, spec_plan.plan, lambda r, bar: simulate_spec(ts, spec_plan, r, progress=bar),
                      sim_settings(runs, mode, seed), key, progress)


def run_simulation(ts, plan, runs, mode, seed, field: str = "sim", progress: bool = False):
    """Simulate ``runs`` closed-loop runs along ``plan``; returns the result and its summary dict
    (in chunks as :func:`run_spec_simulation`).

    ``runs``, ``mode`` and ``seed`` are validated (:class:`tubejax.inputs.SimulationSettings`);
    errors name ``{field}.runs``, ``{field}.disturbance`` or ``{field}.seed``. ``progress``: a bar
    over the runs on stderr.
    """
    from tubejax.analyses.control import simulate

    return _in_chunks(ts, plan, lambda r, bar: simulate(ts, plan, r, progress=bar), sim_settings(runs, mode, seed, field),
                      "spec", progress)


def figure_edge(ts, plan, edge=None) -> int:
    """The index of the edge drawn as Fig. 6.

    ``edge`` (``figures.edge``): ``[i, j]``, the transition from cell ``i`` to cell ``j``; ``None``:
    region 1 -> region 2 as in the paper when that edge exists, else the plan's first edge.

    Raises
    ------
    ConfigError
        ``figures.edge`` names no transition of ``ts``.
    """
    if edge is not None:
        i, j = (int(v) for v in edge)
        k = int(ts.find_edges(i, j))
        if k < 0:
            why = (f"cell ids are 0 .. {ts.n_cells - 1}" if max(i, j) >= ts.n_cells
                   else f"the abstraction has no transition {i} -> {j}")
            raise ConfigError(f"figures.edge: expected a transition [i, j] of the abstraction ({why}), got [{i}, {j}]")
        return k
    d = ts.decomposition
    ones, twos = (np.asarray(d.cells_with_label(label), np.int64) for label in ("1", "2"))
    rows = max(1, 2 ** 20 // max(len(twos), 1))      # pairs (i, j) in blocks of about a million, i-major
    for b in range(0, len(ones), rows):
        k = ts.find_edges(ones[b:b + rows, None], twos[None, :]).ravel()
        if (k >= 0).any():
            return int(k[k >= 0][0])
    return plan.edges[0]


def write_figures(ts, plan, result, out: Path, settings=None) -> list:
    """Figs. 5-7 and the transition graph, PNG + PDF, into ``out``; over a 3-D workspace of boxes
    (a voxel map, or a state space lifted from one: drawn in its position projection) Figs. 5 and 7 have a panel per layer (each 2/3 of ``figures.width`` wide), Fig. 6
    is in 3-D and ``fig9_tubes3d`` (the plan's tubes in 3-D) is written too
    (:func:`tubejax.analyses.plot.view3d.figures_3d`); over a lifted one (a drone) also ``fig10_flight3d``
    (the flight through the whole map with up to 30 runs, :func:`tubejax.analyses.plot.flight3d.plot_flight_3d`).

    ``settings`` (:class:`tubejax.inputs.FigureSettings`, the ``figures`` section; default: its
    defaults) gives the style (``paper``: one-line titles, journal font sizes), the size (or a
    number of journal columns), the PNGs' dpi, Fig. 6's edge, how many runs Fig. 7 draws and the
    3-D view angle.
    """
    from tubejax.inputs import FigureSettings
    from tubejax.analyses.plot import figure_style

    fs = FigureSettings() if settings is None else settings
    with figure_style(fs.style):                # drawn and saved in the style: sizes apply when text is made
        return _write_figures(ts, plan, result, out, fs)


def _write_figures(ts, plan, result, out: Path, fs) -> list:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tubejax.analyses.plot import (RunsStyle, drawn_space, figures_3d, is_layered, new_axes, plot_transition_graph,
                                       plot_trajectories, plot_tube, plot_workspace, save_figure)
    from tubejax.analyses.plot.flight3d import plot_flight_3d

    width, height = fs.size
    edge = figure_edge(ts, plan, fs.edge)
    files = []
    if is_layered(drawn_space(ts.decomposition)[0]):  # 3-D boxes (a voxel map, or a drone's state over one):
                                                      # a panel per layer, the tubes in 3-D, + fig9
        runs = RunsStyle(max_runs=fs.runs_drawn, density=fs.density)
        figs = figures_3d(ts, plan, result, edge, 2 * width / 3, runs, (width, height), view=tuple(fs.view))
        if drawn_space(ts.decomposition)[0] is not ts.decomposition:   # a drone over a map: its flight too
            figs.append(("fig10_flight3d", plot_flight_3d(ts, plan, result, runs=RunsStyle(max_runs=min(
                30, fs.runs_drawn)), size=(1.35 * width, 1.1 * height), view=tuple(fs.view)).figure))
        for stem, fig in figs:
            files += [str(p) for p in save_figure(fig, out, stem, dpi=fs.dpi)]
            plt.close(fig)
        return files
    for stem, draw in [("fig5_workspace", lambda ax: plot_workspace(ts.decomposition, ax,
                                                                     state_constraints=ts.system.state_constraints)),
                       ("fig6_tube", lambda ax: plot_tube(ts, edge, ax)),
                       ("fig7_trajectories", lambda ax: plot_trajectories(ts.decomposition, result, ax, RunsStyle(
                                                                          max_runs=fs.runs_drawn,
                                                                          density=fs.density))),
                       ("transition_graph", lambda ax: plot_transition_graph(ts, ax))]:
        fig, ax = new_axes((width, height))
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
    from tubejax.analyses.plot import (drawn_space, figure_style, is_layered, new_axes, plot_specification,
                                       plot_specification_layers, save_figure)

    fs = FigureSettings() if settings is None else settings
    width, height = fs.size
    with figure_style(fs.style):
        if is_layered(drawn_space(ts.decomposition)[0]):   # 3-D boxes (a voxel map, or a drone over one): a panel per layer
            fig = plot_specification_layers(ts, spec_plan, sim, max_runs=fs.runs_drawn, density=fs.density,
                                            panel_width=2 * width / 3)[0].figure
        else:
            fig, ax = new_axes((width, 1.1 * height))
            plot_specification(ts, spec_plan, sim, ax, max_runs=fs.runs_drawn, density=fs.density)
        files = [str(p) for p in save_figure(fig, out, "fig8_specification", dpi=fs.dpi)]
    plt.close(fig)
    return files


def print_plan(spec_plan) -> None:
    """The plan found, before it is simulated: what it meets (the sequence, formula or patrol), its
    cells and its steps. (The regions a formula's plan meets lie along its tubes, not only in its cells.)"""
    plan = spec_plan.plan
    print(f"plan           : {spec_plan.spec} through cells {cells_text(plan.cells, 24, 6, MORE)} ({plan.cost} steps)", flush=True)


def print_summary(title: str, s: dict) -> None:
    print(f"{title}: runs {s['runs']}, obstacle entries {s['obstacle_entries']}, tube exits "
          f"{s['tube_exits']}, workspace exits {s['workspace_exits']}, reaching all targets "
          f"{s['runs_reaching_all_targets']} ({100.0 * s['runs_reaching_all_targets'] / max(s['runs'], 1):.1f} %)")
    if "runs_satisfying_spec" in s:
        print(f"specification  : {s['spec']}: {s['runs_satisfying_spec']} of {s['runs']} runs satisfy it "
              f"({100.0 * s['runs_satisfying_spec'] / max(s['runs'], 1):.1f} %), avoided-region entries "
              f"{s['avoided_region_entries']}")
    if "lasso" in s:
        lasso = s["lasso"]
        print(f"lasso          : prefix {cells_text(lasso['prefix'], 24, 6, MORE)} ({lasso['prefix_steps']} steps), cycle "
              f"{cells_text(lasso['cycle'], 24, 6, MORE)} ({lasso['cycle_steps']} steps) x {lasso['cycles']} simulated; each run's "
              "words checked by Spot")
    if s.get("outside_state_constraints"):
        print("state constraints: " + ", ".join(f"{c} states outside {k}"
                                                for k, c in s["outside_state_constraints"].items()))


def exit_on_violations(s: dict) -> None:
    """Exit with :data:`EXIT_VIOLATION` and a message on stderr if :func:`summary_violations` finds anything."""
    bad = summary_violations(s)
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
        if not flags.product:                                      # a product system was verified when built
            check_plan_edges(ts, plan)
        if flags.figures.enabled:
            figure_edge(ts, plan, flags.figures.edge)              # a bad figures.edge: refused before simulating
        print_plan(spec_plan)                                  # before the runs, which may take a while
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
    print_summary(f"simulation ({cfg.sim.disturbance})", summary)
    print(f"wrote          : {out / 'simulation.json'}" + (f" and {len(files)} figure files" if files else ""))
    exit_on_violations(summary)


if __name__ == "__main__":
    check_config_files()
    main()
