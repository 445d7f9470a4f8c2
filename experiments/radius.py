"""Every radius from one solve (issue 12) -- a thin Hydra app over :mod:`tubejax.analyses.radius_analysis`.

One batched solve of ``rho*(i, j, L)`` for every candidate (pair, ``L <= L_max``) gives the
transition system at every disturbance radius and every smaller ``L_max``: ``radius.json``
holds every candidate's ``rho*`` (value and certified bracket), the step functions
``n_edges(rho)`` of the tube and open-loop methods and ``n_edges`` against ``L_max``;
``radii=[...]`` writes the verified transition system at each radius to ``DIR/r<radius>/``.

Examples
--------
python experiments/radius.py                                     # the paper map: radius.json
python experiments/radius.py radii=[0.05,0.2] hydra.run.dir=out/radius
python -m tubejax verify out/radius/r0.05
python experiments/simulate.py abstraction_dir=out/radius/r0.2
"""

from __future__ import annotations

import json
import logging
import sys
import time
from pathlib import Path

import hydra
from omegaconf import DictConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import (ConfigError, app_flags, check_config_files, compilation_cache_dir, config_dict,  # noqa: E402
                    config_error, enable_compilation_cache, inputs_from_config, search_dirs, write_json)

log = logging.getLogger("tubejax")
SETTINGS_KEYS = ("radii", "radius_methods", "gap_tol", "exact_curve")


def radius_settings(c: dict):
    """The validated :class:`tubejax.inputs.app_settings.RadiusSettings` of the config's top-level keys."""
    from tubejax.errors import InputModelError
    from tubejax.inputs import validate_section
    from tubejax.inputs.app_settings import RadiusSettings

    try:
        return validate_section(RadiusSettings, {k: c[k] for k in SETTINGS_KEYS if k in c})
    except InputModelError as exc:
        raise config_error(exc) from None


def check_radius_settings(inputs, rs) -> None:
    """Refuse what the radius form does not support (also run before a sweep's first job, experiments/sweep_jobs.py).

    Raises
    ------
    ConfigError
        ``shard.count > 1``, ``min_margin > 0``, ``exact2d`` with ``radii``, a learned ``zshape``.
    """
    from tubejax.lp.evidence.registry import radius_forms

    a = inputs.abstraction
    if a.shard.count != 1:
        raise ConfigError(f"shard.count: expected 1 (experiments/radius.py solves every source cell in one "
                          f"batched solve; shards are for experiments/abstract.py), got {a.shard.count}")
    if a.min_margin != 0:
        raise ConfigError(f"min_margin: expected 0 (the radius form's margin is the radius itself: rho*(i, j, L) "
                          f"is how large W may grow), got {a.min_margin}")
    if rs.radii and a.method not in radius_forms():
        raise ConfigError(f"method: expected {' or '.join(radius_forms())} for the systems at radii ({a.method} has "
                          f"no radius form), got {a.method}")
    if inputs.zshape.learned:
        raise ConfigError(f"zshape.kind: expected box, diamond, cell or regular (experiments/radius.py does not "
                          f"learn Z; zshape={inputs.zshape.kind} runs through experiments/abstract.py), "
                          f"got {inputs.zshape.kind}")


def make_radius_solver(solver, form: str, gap_tol: float):
    """``'highs'`` or the batched engine on the radius form of ``form`` for validated solver settings."""
    if solver.name == "highs":
        return "highs"
    import jax

    from tubejax.lp.batch.batch_solver import RADIUS_OPTIONS, pdhg_solver
    jax.config.update("jax_enable_x64", True)
    enable_compilation_cache(solver.compilation_cache)
    keep = ("pool", "min_bucket", "tail_width", "share", "highs_process")    # iterates in float64: gap_tol is absolute
    return pdhg_solver(form, radius=True, options=RADIUS_OPTIONS._replace(gap_tol=gap_tol),
                       **{k: v for k, v in solver.options().items() if k in keep})


def run_radius(cfg: DictConfig, out: Path):
    """Validate ``cfg``, solve the radius tables, write the systems at ``radii`` and ``radius.json``."""
    from tqdm.auto import tqdm

    from abstract import metrics
    from tubejax.abstraction import cross_sections
    from tubejax.abstraction.preflight import RunBudget, budget_refusal, count_cells
    from tubejax.errors import InputModelError
    from tubejax.inputs import ProblemInputs
    from tubejax.lp.declarations.radius_disturbance import unit_disturbance
    from tubejax.analyses.radius_analysis import (radius_directory, radius_document, record_at_radius,
                                                  RadiusTableOptions, solve_radius_table,
                                                  transition_system_at)

    t0 = time.perf_counter()
    c = config_dict(cfg)
    flags = app_flags(c, figures=True)
    inputs = inputs_from_config(c)
    rs = radius_settings(c)
    a = inputs.abstraction
    if a.solver.name == "pdhg":
        compilation_cache_dir(a.solver.compilation_cache)     # refuse an unusable one before any work
    check_radius_settings(inputs, rs)
    forms = list(rs.radius_methods) + ([a.method] if rs.radii and a.method not in rs.radius_methods else [])
    budget = RunBudget(**flags.budget.model_dump())
    refusal = budget_refusal(None, budget, count_cells(inputs.workspace))     # before the cells are built
    if refusal:
        raise ConfigError(refusal)
    decomp = inputs.build_decomposition()
    system = inputs.build_system()
    try:
        W0, r_in = unit_disturbance(system.W)
    except ValueError as exc:
        raise ConfigError(f"disturbance: {exc}") from None
    records = {}
    for r in rs.radii:
        try:
            records[r] = ProblemInputs.from_record(record_at_radius(inputs.record(), r, r_in), search_dirs())
        except ValueError as exc:              # InputModelError is one too
            msg = exc.problems[0][1] if isinstance(exc, InputModelError) else str(exc)
            raise ConfigError(f"radii: {msg}") from None
    Z = cross_sections(decomp, inputs.zshape.kind, inputs.zshape.scale)
    workers = None
    if a.solver.name == "pdhg" and a.solver.highs_process:
        from tubejax.lp.engines.workers import shared_process_workers
        workers = shared_process_workers()
        workers.submit(0, int, 0)              # start the helper now: its imports overlap the compiles
    tables = {}
    for form in forms:
        bar = tqdm(desc=f"rho* ({form})", unit="LP", disable=not flags.progress, leave=False)
        options = RadiusTableOptions(form=form, L_max=a.L_max, eps_min=a.eps_min, pruning=a.pruning)
        tables[form] = solve_radius_table(decomp, system, Z=Z, options=options,
                                          solver=make_radius_solver(a.solver, form, rs.gap_tol), workers=workers,
                                          progress=bar)
        bar.close()
        if rs.exact_curve:
            tables[form].refine(workers=workers)
        log.info("%s: %d candidates, rho* in %.2f s", form, tables[form].n_instances, tables[form].stats["seconds"])
    systems = {}
    for r, inputs_r in records.items():
        ts = transition_system_at(tables[a.method], r, inputs_r.build_system(), workers=workers)
        ts.inputs = inputs_r.record()          # provenance: the radius is the record's (what verify rebuilds)
        ts.stats.update({"solver": a.solver.name, "compile_seconds": 0.0, "config": c,
                         "n_pruned": int(sum(tables[a.method].stats["pruned"].values()))})
        d = out / radius_directory(r)
        ts.save(d, "transitions")
        write_json(d / "metrics.json", metrics(inputs_r, ts))
        systems[r] = (d.name, ts)
    seconds = time.perf_counter() - t0
    doc = radius_document(tables, inputs.record(), r_in, list(rs.radii) + [r_in], systems,
                          {"seconds": seconds, "settings": rs.model_dump(), "config": c})
    write_json(out / "radius.json", doc)
    if flags.figures.enabled:
        write_radius_figure(json.loads((out / "radius.json").read_text()), out, flags.figures)
    return tables, systems, out / "radius.json"


def write_radius_figure(doc: dict, out: Path, settings=None) -> list:
    """``fig_radius``: the exact ``n_edges(rho)`` curves, the histogram of ``rho*`` and ``n_edges``
    against ``L_max`` (PNG + PDF); ``settings`` (:class:`tubejax.inputs.RadiusFigureSettings`, the
    ``figures`` section) gives the size and the PNG's dpi."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tubejax.inputs import RadiusFigureSettings
    from tubejax.analyses.plot import save_figure
    from tubejax.analyses.plot.radius_curves import plot_n_edges_curves, plot_n_edges_vs_L_max, plot_rho_star_histogram

    settings = RadiusFigureSettings() if settings is None else settings
    fig, axes = plt.subplots(1, 3, figsize=(settings.width, settings.height))
    plot_n_edges_curves(doc, ax=axes[0])
    plot_rho_star_histogram(doc, ax=axes[1])
    plot_n_edges_vs_L_max(doc, form="tube" if "tube" in doc["forms"] else next(iter(doc["forms"])), ax=axes[2])
    files = [str(p) for p in save_figure(fig, out, "fig_radius", dpi=settings.dpi)]
    plt.close(fig)
    return files


@hydra.main(version_base=None, config_path="../conf", config_name="radius")
def main(cfg: DictConfig) -> None:
    out = Path(hydra.core.hydra_config.HydraConfig.get().runtime.output_dir)
    try:
        tables, systems, path = run_radius(cfg, out)
    except (ConfigError, ValueError) as exc:   # every InputError is a ValueError
        log.error("%s", exc)
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    for form, t in tables.items():
        crit = t.critical()
        step = t.n_edges()
        s = t.stats
        print(f"{form:9s}: {t.n_instances} candidates (pair, L <= {t.L_max}), {len(crit.value)} pairs, rho* in "
              f"{s['seconds']:.2f} s (compiling {s['compile_seconds']:.2f} s), exact pairs {int(crit.exact.sum())} "
              f"({s.get('refine_highs_solves', 0)} HiGHS solves, {s.get('refine_seconds', 0.0):.2f} s); "
              f"n_edges(0) = {int(step(0.0))}, largest rho* {step.rho[-1] if len(step.rho) else float('nan'):.6g}")
    for r, (d, ts) in systems.items():
        print(f"radius {r:<7g}: {ts.n_edges} edges ({ts.method}), {ts.stats['n_lps']} HiGHS solves, "
              f"{ts.stats['certified_non_edges']} non-edges by dual bound, proofs {ts.stats['proof']}  -> {out / d}")
    print(f"wrote          : {path}")


if __name__ == "__main__":
    check_config_files()
    main()
