"""Build a verified transition system (Algorithm 2) -- a thin Hydra app over tubejax.

Examples
--------
python experiments/abstract.py                                   # the paper's example
python experiments/abstract.py workspace.map_file=my.txt disturbance.radius=0.1 L_max=6
python experiments/abstract.py solver=highs hydra.run.dir=out/run1
"""

from __future__ import annotations

import json
import logging
import sys
from pathlib import Path

import hydra
from omegaconf import DictConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import (ConfigError, app_flags, check_config_files, config_dict,  # noqa: E402
                    enable_compilation_cache, inputs_from_config, warn_if_disturbance_fits_nowhere, write_json)

log = logging.getLogger("tubejax")
PAPER_COUNTS = {"states": 67, "transitions": 655}


def run_abstraction(cfg: DictConfig, out: Path):
    """Validate ``cfg`` (:func:`common.inputs_from_config`), run
    :func:`tubejax.abstraction.build_abstraction`, write the files."""
    from tubejax.abstraction import build_abstraction

    c = config_dict(cfg)
    flags = app_flags(c)
    inputs = inputs_from_config(c)
    decomp = inputs.build_decomposition()
    system = inputs.build_system()
    warn_if_disturbance_fits_nowhere(decomp, system.W)
    solve = make_solver(inputs.abstraction)
    partial = out / "edges.partial.jsonl"
    partial.write_text("")

    def on_round(L, edges, tubes):  # finished work is on disk after every round
        with partial.open("a") as f:
            for e in edges:
                f.write(json.dumps(e.to_json()) + "\n")

    ts = build_abstraction(decomp, system, **inputs.abstraction_kwargs(), solve_batch=solve,
                           progress=flags.progress, on_round=on_round)
    ts.stats["solver"] = inputs.abstraction.solver.name
    solver_stats = dict(getattr(solve, "stats", None) or {})
    ts.stats["compile_seconds"] = float(solver_stats.get("compile_seconds", 0.0))
    if solver_stats:
        ts.stats["solver_stats"] = solver_stats
    ts.stats["config"] = c
    ts.inputs = inputs.record()                    # provenance: files by path and SHA-256 (what verify rebuilds)
    jpath, npath = ts.save(out, "transitions")
    write_json(out / "metrics.json", metrics(inputs, ts))
    partial.unlink()
    return ts, jpath, npath


def make_solver(settings):
    """The batch solver for validated :class:`tubejax.inputs.AbstractionSettings`.

    ``method``: tube | openloop | exact2d; ``solver.name``: highs | pdhg. ``verify='all'`` makes
    the PDHG path re-solve every certified verdict with HiGHS and count disagreements (HiGHS
    itself is the reference, so nothing changes for ``solver=highs``). exact2d is a polygon
    computation and ignores ``solver``.
    """
    method, solver = settings.method, settings.solver
    if method == "exact2d":
        from tubejax.exact2d import exact2d_solve_batch
        return exact2d_solve_batch
    if solver.name == "highs":
        if method == "tube":
            from tubejax.lp.evidence.verdict import highs_solve_batch
            return highs_solve_batch
        from tubejax.lp.formulations.openloop.dense import openloop_solve_batch
        return openloop_solve_batch
    import jax

    from tubejax.lp.solvers.batched import PdhgBatchSolver
    from tubejax.lp.formulations.openloop.pdhg import openloop_pdhg_solver
    jax.config.update("jax_enable_x64", True)
    enable_compilation_cache(solver.compilation_cache)
    cls = PdhgBatchSolver if method == "tube" else openloop_pdhg_solver
    return cls(exact=settings.verify == "all", **solver.options())


def metrics(inputs, ts) -> dict:
    """One flat row per job, for experiments/aggregate.py."""
    s = ts.stats
    Ls = [e.L for e in ts.edges]
    margins = [e.margin for e in ts.edges]
    d, a = inputs.disturbance, inputs.abstraction
    return {
        "method": a.method, "solver": a.solver.name, "system": inputs.system.name,
        "workspace": ts.decomposition.name, "disturbance": d.kind,
        "radius": float(getattr(d, "radius", getattr(d, "half_width", float("nan")))),
        "zshape": inputs.zshape.kind, "L_max": a.L_max, "pruning": a.pruning,
        "n_cells": s["n_cells"], "n_edges": s["n_edges"], "n_lps": s["n_lps"],
        "n_pruned": s["n_pruned"], "n_zero_margin": s["n_zero_margin"],
        "mean_L": float(sum(Ls) / len(Ls)) if Ls else float("nan"),
        "mean_margin": float(sum(margins) / len(margins)) if margins else float("nan"),
        "seconds": s["seconds"], "compile_seconds": s["compile_seconds"],
        "edges": [[e.src, e.dst, e.L] for e in ts.edges],
    }


@hydra.main(version_base=None, config_path="../conf", config_name="config")
def main(cfg: DictConfig) -> None:
    out = Path(hydra.core.hydra_config.HydraConfig.get().runtime.output_dir)
    try:
        ts, jpath, npath = run_abstraction(cfg, out)
    except (ConfigError, ValueError) as exc:   # every InputError (ConfigError, GridMapError, ...) is a ValueError
        log.error("%s", exc)
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(2)
    s = ts.stats
    print(f"workspace      : {ts.decomposition.name}")
    print(f"states         : {s['n_cells']:6d}   (paper: {PAPER_COUNTS['states']})")
    print(f"transitions    : {s['n_edges']:6d}   (paper: {PAPER_COUNTS['transitions']}; the maps differ, see README)")
    print(f"LPs solved     : {s['n_lps']:6d}   pruned (pair, L): {s['n_pruned']}  {s['pruned']}")
    print(f"zero-margin    : {s['n_zero_margin']:6d}   unconfirmed: {s['n_unconfirmed']}")
    print(f"seconds        : {s['seconds']:.2f}   (compiling: {s['compile_seconds']:.2f}; solver {s['solver']})")
    if "solver_stats" in s:
        st = s["solver_stats"]
        print(f"PDHG           : certified infeasible {st.get('certified_infeasible')}, certified feasible "
              f"{st.get('certified_feasible')} (HiGHS-confirmed), sent to HiGHS {st.get('sent_to_highs')}, "
              f"HiGHS disagreements {st.get('highs_disagreements')}")
    print(f"wrote          : {jpath}\n                 {npath}")


if __name__ == "__main__":
    check_config_files()
    main()
