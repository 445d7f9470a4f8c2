"""How conservative is each method? The reach-avoid limit beside every method's winning set -- a thin Hydra app.

Examples
--------
python experiments/conservatism.py                                   # the paper map, target 6, r = 0.2
python experiments/conservatism.py workspace.map_file=my.txt target=2 avoid=[4] disturbance.radius=0.1
python experiments/conservatism.py methods=[tube] 'abstraction_dirs={tube: out/run1}'   # read a run
python experiments/conservatism.py -m disturbance.radius=0.05,0.1,0.15,0.2,0.25,0.3,0.35 \
    hydra.sweep.dir=out/ladder && python experiments/aggregate.py out/ladder   # fraction_of_limit.png

The limit ``R_∞`` of robust reach-avoid (docs/math/limit.md) is computed as an outer approximation
(:func:`tubejax.analyses.conservatism.reach_avoid_limit`); each method in ``methods`` is run as
``experiments/abstract.py`` would run it into ``<method>/`` beside the output (or read from
``abstraction_dirs``), and its winning cells (those with a path to a target cell,
:func:`tubejax.analyses.conservatism.winning_set`) are compared with the limit. Writes
``conservatism.json``::

    {"limit": {"area", "iterations", "converged"}, "free_area", "target_area",
     "methods": {METHOD: {"winning_area", "winning_cells", "fraction_of_limit"}}, "provenance": {...}}

(``winning_cells``: the cell ids of ``<method>/transitions.json``; ``fraction_of_limit`` is
``null`` when the limit did not converge) and ``fig_conservatism.png|pdf``. A winning cell
outside the limit is a bug in the limit or the method: it is named and the app exits with code 1.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig, OmegaConf

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import (ConfigError, app_flags, check_config_files, config_dict, config_error,  # noqa: E402
                    inputs_from_config, write_json)

log = logging.getLogger("tubejax")
EXIT_OUTSIDE = 1


def conservatism_settings(c: dict):
    """The validated :class:`tubejax.inputs.app_settings.ConservatismSettings` of the resolved config ``c``."""
    from tubejax.errors import InputModelError
    from tubejax.inputs import validate_section
    from tubejax.inputs.app_settings import ConservatismSettings

    data = {k: c[k] for k in ConservatismSettings.model_fields if k in c}
    try:
        return validate_section(ConservatismSettings, data)
    except InputModelError as exc:
        raise config_error(exc) from None


def check_conservatism(c: dict, inputs, cs) -> tuple:
    """Refuse before any work what the limit cannot take: not 2-D, a singular ``A``, unknown labels."""
    from tubejax.analyses.conservatism.limit import _inverse

    decomp = inputs.build_decomposition()
    if decomp.dim != 2:
        raise ConfigError(f"workspace: the limit is computed in 2-D (grid maps, polygon workspaces), got a "
                          f"{decomp.dim}-D workspace")
    system = inputs.build_system()
    try:
        _inverse(system.A)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    have = sorted({str(l) for l in decomp.labels if l is not None})
    for key, lab in [("target", cs.target)] + [("avoid", a) for a in cs.avoid]:
        if str(lab) not in have:
            raise ConfigError(f"{key}: no cell carries the label {str(lab)!r} (labels present: {have})")
    return decomp, system


def method_run(cfg: DictConfig, c: dict, method: str, directory, out: Path):
    """The transition system of ``method``: read from ``directory`` (checked as verify's cheap checks, and
    for the same cells and system), or run as ``experiments/abstract.py`` into ``out/<method>``."""
    from abstract import run_abstraction
    from simulated_abstraction import abstraction_dir
    from tubejax.verify.verifier import load_checked

    if directory is not None:
        d = abstraction_dir(directory)
        try:
            ts = load_checked(d)
        except (OSError, ValueError) as exc:
            why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ConfigError(f"abstraction_dirs.{method}: cannot load the transition system: {why}") from None
        if ts.method != method:
            raise ConfigError(f"abstraction_dirs.{method}: {d} holds a run of method {ts.method!r}")
        return ts, d
    c = dict(c)
    c["method"] = {"name": method}
    ts, jpath, _ = run_abstraction(OmegaConf.create(c), out / method)
    return ts, jpath.parent


def same_problem(ts, decomp, system) -> str | None:
    """Why ``ts`` is not a run of the limit's problem (other cells or another system), or None."""
    if ts.n_cells != decomp.n_cells or any(
            not (P.vertices.shape == Q.vertices.shape and (abs(P.vertices - Q.vertices) <= 1e-12).all())
            for P, Q in zip(ts.decomposition.cells, decomp.cells)):
        return "its cells differ from the workspace's"
    diff = ts.system.differences(system)
    return f"its system differs in {', '.join(diff)}" if diff else None


def run_conservatism(cfg: DictConfig, out: Path) -> tuple[dict, list]:
    """Validate ``cfg``, compute the limit and every method's winning set, write the files.

    Returns ``(document, outside)``: ``conservatism.json``'s content and the winning cells outside
    the limit (``[(method, cell, area)]``, empty unless something is wrong).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from tubejax.analyses.conservatism import cells_outside, reach_avoid_limit, winning_set
    from tubejax.analyses.plot import save_figure
    from tubejax.analyses.plot.conservatism import plot_limit
    from tubejax.lp.evidence.registry import series_name

    c = config_dict(cfg)
    flags = app_flags(c)
    cs = conservatism_settings(c)
    inputs = inputs_from_config(c)
    decomp, system = check_conservatism(c, inputs, cs)
    dirs = cs.abstraction_dirs or {}
    if unknown := sorted(set(dirs) - set(cs.methods)):
        raise ConfigError(f"abstraction_dirs: {unknown[0]!r} is not among methods {cs.methods}")
    target, avoid = str(cs.target), [str(a) for a in cs.avoid]
    lim = reach_avoid_limit(decomp, system, target, avoid, sides=cs.sides, max_iterations=cs.max_iterations,
                            area_tol=cs.area_tol, progress=flags.progress)
    log.info("limit: area %.6f of %.6f free, %d iterations, converged %s (%.1f s)", lim.area, lim.free_area,
             lim.iterations, lim.converged, lim.seconds)
    doc = {"limit": lim.summary(), "free_area": lim.free_area, "target_area": lim.target_area, "methods": {}}
    wins, outside = {}, []
    for method in cs.methods:
        ts, where = method_run(cfg, c, method, dirs.get(method), out)
        if why := same_problem(ts, decomp, system):
            raise ConfigError(f"abstraction_dirs.{method}: {where} is not a run of this problem: {why}")
        win = winning_set(ts, target, avoid)
        name = series_name(method, inputs.zshape.kind)
        wins[name] = win
        doc["methods"][method] = win.summary(lim.area if lim.converged else None)
        if lim.converged:
            outside += [(method, cell, a) for cell, a in cells_outside(win, lim.geometry, decomp)]
        log.info("%s: %d winning cells, area %.6f (%s)", name, len(win.cells), win.area, where)
    write_json(out / "conservatism.json", doc)
    if cs.figures:
        fig, ax = plt.subplots(figsize=(8.0, 5.5))
        plot_limit(decomp, lim, wins, ax=ax)
        r = getattr(inputs.disturbance, "radius", getattr(inputs.disturbance, "half_width", None))
        ax.set_title(f"{Path(decomp.name).name}: target {target}"
                     + (f", avoid {', '.join(avoid)}" if avoid else "")
                     + (f", W {inputs.disturbance.kind} {r:g}" if r is not None else ""), fontsize=9)
        fig.tight_layout()
        save_figure(fig, out, "fig_conservatism")
        plt.close(fig)
    return doc, outside


@hydra.main(version_base=None, config_path="../conf", config_name="conservatism")
def main(cfg: DictConfig) -> None:
    out = Path(hydra.core.hydra_config.HydraConfig.get().runtime.output_dir)
    try:
        doc, outside = run_conservatism(cfg, out)
    except (ConfigError, ValueError) as exc:   # every InputError is a ValueError
        log.error("%s", exc)
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    lim = doc["limit"]
    print(f"limit          : area {lim['area']:.4f} of {doc['free_area']:.4f} free (target {doc['target_area']:.4f}), "
          f"{lim['iterations']} iterations, " + ("converged" if lim["converged"] else
                                                   "NOT converged: not the limit, no fraction reported"))
    for method, m in doc["methods"].items():
        frac = "-" if m["fraction_of_limit"] is None else f"{m['fraction_of_limit']:.3f}"
        print(f"{method:15s}: {len(m['winning_cells']):5d} winning cells, area {m['winning_area']:.4f}, "
              f"fraction of the limit {frac}")
    print(f"wrote          : {out / 'conservatism.json'}")
    if outside:
        for method, cell, a in outside:
            msg = f"{method}: winning cell {cell} lies partly outside the limit ({a:.3g} of its area): a bug"
            log.error("%s", msg)
            print(f"error: {msg}", file=sys.stderr)
        sys.exit(EXIT_OUTSIDE)


if __name__ == "__main__":
    check_config_files()
    main()
