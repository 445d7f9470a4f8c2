"""Profile of the LP layer on one rooms-and-corridors map (a script, not a test).

Runs :func:`tubejax.abstraction.build_abstraction` with the batched PDHG solver as
``experiments/scaling.py`` builds it, and reports

* per round: LPs, wall seconds of the solver call, PDHG device seconds (inside the jitted
  calls) and PDHG host seconds (the rest of the PDHG part: setup, refills, certificates);
* CPU seconds of the main process (per thread group) and of the HiGHS helper process(es),
  against the wall time of the run (how busy the cores were);
* the HiGHS path split, measured in this process on a sample of the instances that went to
  HiGHS (edges and non-edges as in the run): pickling, LP build, HiGHS solve, float check,
  exact proof (with its sub-steps).

Usage
-----
python experiments/profile_lp.py --size 1000 --sample 400
python experiments/profile_lp.py --divisions 4444 --sample 200
"""

from __future__ import annotations

import argparse
import json
import pickle
import statistics
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _workspace(args):
    import yaml

    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set
    from tubejax.model.workspace import box_grid, parse_grid_map
    from tubejax.model.workspace.generate import rooms_and_corridors_map

    if args.divisions:
        ws = yaml.safe_load((ROOT / "conf" / "workspace" / "boxgrid4d.yaml").read_text())
        cfg = yaml.safe_load((ROOT / "conf" / "system" / "double_integrator.yaml").read_text())
        decomp = box_grid(ws["lower"], ws["upper"], [int(c) for c in args.divisions],
                          obstacles=[tuple(o) for o in ws["obstacles"]], name="boxgrid4d")
        system = LinearSystem(A=np.array(cfg["A"], float), B=np.array(cfg["B"], float),
                              U=box_input_set(cfg["U"]["bound"], 2), W=Ball(4, 0.02))
        return decomp, system, dict(zshape="cell", L_max=8)
    decomp = parse_grid_map(rooms_and_corridors_map(args.size, seed=args.seed), name="rooms")
    system = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    return decomp, system, dict(zshape="box", L_max=10)


def _cpu(proc) -> dict:
    """CPU seconds of a psutil process: total and per thread (by thread id)."""
    t = proc.cpu_times()
    return {"total": t.user + t.system,
            "threads": {th.id: th.user_time + th.system_time for th in proc.threads()}}


def highs_split(problems: list, reps: int = 1) -> dict:
    """Median milliseconds of each step of the HiGHS verdict on ``problems`` (in this process)."""
    from tubejax.lp.evidence import verdict as vmod
    from tubejax.lp.evidence.prove import prove_with_basis
    from tubejax.lp.declarations.tube_lp import build_tube_lp, tube_violation
    from tubejax.lp.engines.highs import solve_margin_lp

    steps = defaultdict(list)
    kinds = defaultdict(int)
    for p in problems:
        t0 = time.perf_counter()
        blob = pickle.dumps((0, 0, vmod.highs_verdict, (p, "highs")), protocol=pickle.HIGHEST_PROTOCOL)
        pickle.loads(blob)
        t1 = time.perf_counter()
        lp = build_tube_lp(p)
        t2 = time.perf_counter()
        res = solve_margin_lp(lp, basis_min_margin=-vmod.CLEAR_MARGIN)
        t3 = time.perf_counter()
        steps["pickle_roundtrip"].append(t1 - t0)
        steps["pickle_bytes"].append(len(blob))
        steps["build"].append(t2 - t1)
        steps["solve"].append(t3 - t2)
        if res.status != "Optimal" or res.margin < -vmod.CLEAR_MARGIN:
            kinds["non-edge"] += 1
            continue
        ev = lp.index.split(res.x)
        t4 = time.perf_counter()
        viol = tube_violation(p, ev)
        t5 = time.perf_counter()
        steps["float_check"].append(t5 - t4)
        if viol > vmod.VERIFY_TOL:
            kinds["unconfirmed/near"] += 1
            continue
        kinds["edge"] += 1
        proof = prove_with_basis(p, lp, res, ev)
        t6 = time.perf_counter()
        steps["prove_with_basis"].append(t6 - t5)
        _, pr = vmod._prove(p, lp, res, ev, tube_violation, viol)
        t7 = time.perf_counter()
        steps["prove_total"].append(t7 - t6)
        kinds["proof: " + pr.note.split(";")[0]] += 1
        del proof
        t8 = time.perf_counter()
        vmod.highs_verdict(p)
        steps["verdict_total"].append(time.perf_counter() - t8)
    out = {k: 1e3 * statistics.median(v) for k, v in steps.items() if k != "pickle_bytes"}
    out["pickle_bytes_median"] = statistics.median(steps["pickle_bytes"]) if steps["pickle_bytes"] else 0
    out["mean_ms"] = {k: 1e3 * statistics.fmean(v) for k, v in steps.items() if k != "pickle_bytes"}
    out["counts"] = dict(kinds)
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=1000, help="free cells of the rooms map")
    ap.add_argument("--divisions", default="", help="a 4-D box grid instead, e.g. 4444")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sample", type=int, default=400, help="HiGHS instances profiled in-process")
    ap.add_argument("--out", default="", help="write the numbers as JSON here")
    ap.add_argument("--dump", default="", help="pickle the profiled HiGHS instances here")
    args = ap.parse_args(argv)

    import jax
    import psutil
    import yaml

    jax.config.update("jax_enable_x64", True)
    sys.path.insert(0, str(ROOT / "experiments"))
    from common import enable_compilation_cache

    from tubejax.abstraction import build_abstraction
    from tubejax.lp.evidence.verdict import Pending
    from tubejax.lp.batch.batch_solver import PdhgBatchSolver
    from tubejax.lp.engines.workers import shared_process_workers

    decomp, system, kw = _workspace(args)
    opts = yaml.safe_load((ROOT / "conf" / "solver" / "pdhg.yaml").read_text())
    enable_compilation_cache(opts.pop("compilation_cache", None))
    solver = PdhgBatchSolver(**{k: v for k, v in opts.items() if k != "name"})
    rounds, sent = [], []
    me = psutil.Process()

    def recording(problems, progress=None, **k):
        s0 = dict(solver.stats)
        t0 = time.perf_counter()
        res = solver(problems, progress=progress, **k)
        wall = time.perf_counter() - t0
        s1 = solver.stats
        d = {key: s1[key] - s0[key] for key in ("pdhg_seconds", "device_seconds", "compile_seconds",
                                               "highs_wait_seconds", "n_lps", "certified_infeasible")}
        d["host_seconds"] = d["pdhg_seconds"] - d["device_seconds"]
        rounds.append({"L": int(problems[0].L), "wall": wall, **d})
        for p, v in zip(problems, res):
            if isinstance(v, Pending) or v.provenance != "pdhg-certificate":
                sent.append((p, v))
        return res

    recording.supports_deferred = True
    recording.stats = solver.stats
    cpu0 = _cpu(me)
    t0 = time.perf_counter()
    ts = build_abstraction(decomp, system, solve_batch=recording, progress=False, **kw)
    wall = time.perf_counter() - t0
    cpu1 = _cpu(me)
    workers = shared_process_workers()
    helpers = [psutil.Process(p.pid) for p in getattr(workers, "processes", lambda: [])()] \
        if hasattr(workers, "processes") else ([psutil.Process(workers._proc.pid)] if workers._proc else [])
    helper_cpu = sum(h.cpu_times().user + h.cpu_times().system for h in helpers)
    threads = {tid: sec - cpu0["threads"].get(tid, 0.0) for tid, sec in cpu1["threads"].items()}
    top = sorted(threads.values(), reverse=True)
    s = ts.stats
    report = {
        "cells": s["n_cells"], "lps": s["n_lps"], "edges": s["n_edges"], "wall_seconds": wall,
        "seconds_before_first_lp": s["seconds_before_first_lp"], "problem_seconds": s["problem_seconds"],
        "solve_seconds": s["solve_seconds"], "confirm_wait_seconds": s["confirm_wait_seconds"],
        "pdhg_lps_per_second": s.get("pdhg_lps_per_second"), "highs_lps_per_second": s.get("highs_lps_per_second"),
        "n_highs_solves": s.get("n_highs_solves"), "verdicts": s["verdicts"], "provenance": s["provenance"],
        "solver_stats": {k: v for k, v in solver.stats.items() if not isinstance(v, dict)},
        "status_counts": solver.stats["status_counts"],
        "main_cpu_seconds": cpu1["total"] - cpu0["total"], "main_top_threads_cpu": top[:6],
        "helper_cpu_seconds": helper_cpu, "n_helpers": len(helpers),
        "rounds": rounds,
    }
    rng = np.random.default_rng(0)
    pick = rng.choice(len(sent), size=min(args.sample, len(sent)), replace=False) if sent else []
    sample = [sent[k][0] for k in sorted(pick)]
    if args.dump:
        Path(args.dump).write_bytes(pickle.dumps(sample, protocol=pickle.HIGHEST_PROTOCOL))
    report["highs_split_ms"] = highs_split(sample)
    print(json.dumps(report, indent=1, default=float))
    if args.out:
        Path(args.out).write_text(json.dumps(report, indent=1, default=float))


if __name__ == "__main__":
    main()
