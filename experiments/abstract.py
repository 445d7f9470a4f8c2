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
from omegaconf import DictConfig, OmegaConf

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import (ConfigError, build_system, build_workspace, check_L_max, enable_compilation_cache,  # noqa: E402
                    write_json)

log = logging.getLogger("tubejax")
PAPER_COUNTS = {"states": 67, "transitions": 655}


def run_abstraction(cfg: DictConfig, out: Path):
    """Unpack ``cfg``, run :func:`tubejax.abstraction.build_abstraction`, write the files."""
    from tubejax.abstraction import build_abstraction

    L_max = check_L_max(cfg.L_max)
    decomp = build_workspace(cfg.workspace)
    system = build_system(cfg)
    solve = make_solver(cfg.method.name, cfg.solver, str(cfg.verify))
    partial = out / "edges.partial.jsonl"
    partial.write_text("")

    def on_round(L, edges, tubes):  # finished work is on disk after every round
        with partial.open("a") as f:
            for e in edges:
                f.write(json.dumps(e.to_json()) + "\n")

    ts = build_abstraction(decomp, system, zshape=cfg.zshape.kind, z_scale=float(cfg.zshape.scale),
                           L_max=L_max, eps_min=float(cfg.eps_min), pruning=bool(cfg.pruning),
                           solve_batch=solve, progress=bool(cfg.progress), on_round=on_round,
                           method=cfg.method.name)
    ts.stats["solver"] = cfg.solver.name
    solver_stats = dict(getattr(solve, "stats", None) or {})
    ts.stats["compile_seconds"] = float(solver_stats.get("compile_seconds", 0.0))
    if solver_stats:
        ts.stats["solver_stats"] = solver_stats
    ts.stats["config"] = OmegaConf.to_container(cfg, resolve=True)
    jpath, npath = ts.save(out, "transitions")
    write_json(out / "metrics.json", metrics(cfg, ts))
    partial.unlink()
    return ts, jpath, npath


def make_solver(method: str, solver_cfg, verify: str = "none"):
    """The batch solver for ``method`` (tube | openloop | exact2d) and ``solver`` (highs | pdhg).

    ``verify='all'`` makes the PDHG path re-solve every certified verdict with HiGHS and count
    disagreements (HiGHS itself is the reference, so nothing changes for ``solver=highs``).
    exact2d is a polygon computation and ignores ``solver``.
    """
    if verify not in ("none", "all"):
        raise ConfigError(f"verify: expected none or all, got {verify!r}")
    if method not in ("tube", "openloop", "exact2d"):
        raise ConfigError(f"method: expected tube, openloop or exact2d, got {method!r}")
    if solver_cfg.name not in ("highs", "pdhg"):
        raise ConfigError(f"solver: expected highs or pdhg, got {solver_cfg.name!r}")
    if method == "exact2d":
        from tubejax.exact2d import exact2d_solve_batch
        return exact2d_solve_batch
    if solver_cfg.name == "highs":
        if method == "tube":
            from tubejax.lp.evidence.verdict import highs_solve_batch
            return highs_solve_batch
        from tubejax.lp.formulations.openloop.dense import openloop_solve_batch
        return openloop_solve_batch
    import jax

    from tubejax.lp.solvers.batched import PdhgBatchSolver
    from tubejax.lp.formulations.openloop.pdhg import openloop_pdhg_solver
    jax.config.update("jax_enable_x64", True)
    opts = {k: v for k, v in OmegaConf.to_container(solver_cfg, resolve=True).items()
            if k not in ("name", "compilation_cache")}
    enable_compilation_cache(solver_cfg.get("compilation_cache"))
    cls = PdhgBatchSolver if method == "tube" else openloop_pdhg_solver
    return cls(exact=verify == "all", **opts)


def metrics(cfg: DictConfig, ts) -> dict:
    """One flat row per job, for experiments/aggregate.py."""
    s = ts.stats
    Ls = [e.L for e in ts.edges]
    margins = [e.margin for e in ts.edges]
    d = cfg.disturbance
    return {
        "method": cfg.method.name, "solver": cfg.solver.name, "system": cfg.system.name,
        "workspace": ts.decomposition.name, "disturbance": d.kind,
        "radius": float(d.get("radius", d.get("half_width", float("nan")))),
        "zshape": cfg.zshape.kind, "L_max": int(cfg.L_max), "pruning": bool(cfg.pruning),
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
    except (ConfigError, ValueError) as exc:
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
    main()
