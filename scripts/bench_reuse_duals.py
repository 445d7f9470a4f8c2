"""The batched solver with and without reused duals, side by side (the tube form without its ``dual_key``).

    python scripts/bench_reuse_duals.py                         # 2-D rooms ~200 cells and 4-D 4x4x4x4
    python scripts/bench_reuse_duals.py --maps rooms:200 --repeats 3

Builds each abstraction with ``PdhgBatchSolver()`` and with one whose form has no ``dual_key``,
alternating, after one untimed warm-up run (compilation). Prints per map the medians of: the
instances settled by a reused dual, the pool's slot iterations, the PDHG seconds (compilation
excluded) and the whole abstraction's seconds, their ratios, and whether the two transition
systems have the same edges and horizons. ``rooms:N`` is the seeded rooms-and-corridors map of
about ``N`` cells (``W`` a ball of radius 0.2, box ``Z``, ``L_max = 10``; translates are settled by
class, as in every run); ``grid:DDDD`` the 4-D double integrator on
``conf/workspace/boxgrid4d.yaml`` (``r = 0.02``, ``zshape = cell``, ``L_max = 8``).
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import jax
import numpy as np
import yaml

from tubejax.abstraction import build_abstraction
from tubejax.lp.batch.batch_solver import PdhgBatchSolver
from tubejax.model.geometry import Ball
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import box_grid, parse_grid_map
from tubejax.model.workspace.generate import rooms_and_corridors_map

ROOT = Path(__file__).resolve().parents[1]


def problem(spec: str):
    """``(decomposition, system, keyword arguments of build_abstraction)`` of ``rooms:N`` or ``grid:DDDD``."""
    kind, _, size = spec.partition(":")
    if kind == "rooms":
        decomp = parse_grid_map(rooms_and_corridors_map(int(size), seed=0), name=spec)
        system = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
        return decomp, system, dict(zshape="box", L_max=10)
    if kind == "grid":
        ws = yaml.safe_load((ROOT / "conf/workspace/boxgrid4d.yaml").read_text())
        cfg = yaml.safe_load((ROOT / "conf/system/double_integrator.yaml").read_text())
        decomp = box_grid(ws["lower"], ws["upper"], [int(c) for c in size],
                          obstacles=[tuple(o) for o in ws["obstacles"]], name=spec)
        system = LinearSystem(A=np.array(cfg["A"], float), B=np.array(cfg["B"], float),
                              U=box_input_set(cfg["U"]["bound"], 2), W=Ball(4, 0.02))
        return decomp, system, dict(zshape="cell", L_max=8)
    raise SystemExit(f"--maps: expected rooms:N or grid:DDDD, got {spec!r}")


def run(decomp, system, kw, reuse: bool) -> tuple[dict, set]:
    solver = PdhgBatchSolver(highs_process=False)
    if not reuse:                                       # no dual key: no dual reused (this script's variant)
        solver.form = solver.form._replace(dual_key=None)
    t = time.perf_counter()
    ts = build_abstraction(decomp, system, solve_batch=solver, progress=False, **kw)
    st = solver.stats
    row = {"reused": st["duals_reused"], "slot iterations": st["slot_iterations"],
           "PDHG s": st["pdhg_seconds"], "total s": time.perf_counter() - t - st["compile_seconds"]}
    return row, {(e.src, e.dst, e.L) for e in ts.edges}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--maps", default="rooms:200,grid:4444")
    ap.add_argument("--repeats", type=int, default=1)
    args = ap.parse_args()
    jax.config.update("jax_enable_x64", True)
    for spec in args.maps.split(","):
        decomp, system, kw = problem(spec)
        run(decomp, system, kw, True)                        # warm-up: compile every shape
        rows: dict = {True: [], False: []}
        edges: dict = {}
        for _ in range(args.repeats):
            for reuse in (True, False):
                row, edges[reuse] = run(decomp, system, kw, reuse)
                rows[reuse].append(row)
        med = {r: {k: statistics.median(x[k] for x in rows[r]) for k in rows[r][0]} for r in rows}
        print(f"{spec} ({decomp.n_cells} cells, {len(edges[True])} edges, median of {args.repeats}):")
        for k in med[True]:
            on, off = med[True][k], med[False][k]
            ratio = f"{off / on:.2f}x" if on and k != "reused" else "-"
            print(f"  {k:>16}: reuse {on:>12,.1f}   no reuse {off:>12,.1f}   no reuse / reuse {ratio}")
        print(f"  same edges and horizons: {edges[True] == edges[False]}", flush=True)


if __name__ == "__main__":
    main()
