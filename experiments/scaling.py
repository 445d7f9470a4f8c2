"""Benchmark: how the abstraction scales with the number of cells (a script, not a test).

For seeded rooms-and-corridors grid maps of about 100 ... 10,000 free cells (the paper's
system, r = 0.2, box Z, L_max = 10), 4-D box grids for the double integrator
(conf/system/double_integrator.yaml, r = 0.02, zshape = cell, L_max = 8) and, with
``--buildings``, generated 3-D buildings (voxel maps, ``tubejax.model.workspace.generate.building_map``,
three storeys; conf/system/integrator3d.yaml, r = 0.2, box Z, L_max = 5), each size runs in a
fresh subprocess with the batched PDHG solver as experiments/abstract.py builds it
(conf/solver/pdhg.yaml, persistent compilation cache on) and prints: cells, candidate pairs,
LPs solved, instances settled by their translation class (``by class``,
:mod:`tubejax.abstraction.translation_classes`), edges, the edges proved
by exact translation instead of a HiGHS solve of their own (:mod:`tubejax.lp.evidence.translate_verdicts`;
``--no-translation-proofs`` solves them), LPs per edge, seconds
before the first LP, problem-building and solver seconds, total seconds, LP/s of PDHG and of
HiGHS, the share of the instances PDHG ran that it decided itself (certified infeasible, or
stopped at a likely edge: a feasible point or a margin near 0; the rest hit its iteration cap
or numerical trouble and went to HiGHS), peak memory (the largest summed RSS of the worker and its HiGHS helper processes,
sampled with psutil, and the worker's own ru_maxrss), and the seconds of the proof pass that
follows the abstraction (``TransitionSystem.prove``: the safe sets of the edges; not in the
total).
Where it stays under ``--highs-timeout`` (default 300 s), the sequential HiGHS path
(``tubejax.lp.evidence.verdict.highs_solve_batch``) runs too, and the table shows HiGHS / PDHG.
Finally it fits the growth exponent of total time against cells (log-log least squares over
1,000 .. 10,000 cells) and saves a log-log plot (PNG and PDF), the table (Markdown) and all
numbers (JSON) to ``--out``.
With ``--product``, each 4-D grid also runs the product path (docs/math/product.md: factor LPs per axis
group with the same solver, their join, the joint LPs of blocked bounding boxes) and a side-by-side table
(``OUT/product.md``) shows both edge counts, the joint edges the product path misses (0 by the theorem),
the edges whose ``L`` is larger (0) or smaller there, both times, the speed-up and the factor LPs.

Usage
-----
python experiments/scaling.py                                # everything up to 10,000 cells
python experiments/scaling.py --max-cells 2500 --no-highs --repeats 3
python experiments/scaling.py --sizes 1000,10000 --divisions 4444,6666 --out outputs/scaling
python experiments/scaling.py --sizes '' --divisions '' --buildings 2000,20000 --max-cells 25000
python experiments/scaling.py --sizes '' --divisions 6766 --product --no-highs   # joint LPs vs the product path
python experiments/scaling.py --sizes '' --divisions '' --drone conf/workspace/maps/building3d.txt:10,8,5  # drone phases
"""

from __future__ import annotations

import argparse
import json
import resource
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SIZES = (100, 400, 1000, 2500, 5000, 10000)
DIVISIONS = ("2222", "3333", "4444", "5555", "6666")
#: The cell range of each kind's growth exponent.
FIT_RANGE = {"building3d": (2000, 20000)}


def _four_d_cells(div: str) -> int:
    sys.path.insert(0, str(ROOT))
    from tubejax.model.workspace import box_grid
    import yaml

    ws = yaml.safe_load((ROOT / "conf" / "workspace" / "boxgrid4d.yaml").read_text())
    return box_grid(ws["lower"], ws["upper"], [int(c) for c in div],
                    obstacles=[tuple(o) for o in ws["obstacles"]]).n_cells


# -- worker (one size, one solver, in its own process) -------------------------------------------

def worker(spec: dict) -> dict:
    """Build one workspace and run the abstraction; returns the row of numbers."""
    import jax
    import yaml

    jax.config.update("jax_enable_x64", True)
    sys.path.insert(0, str(ROOT / "experiments"))
    from common import enable_compilation_cache

    from tubejax.abstraction import build_abstraction
    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set
    from tubejax.model.workspace import box_grid, parse_grid_map
    from tubejax.model.workspace.generate import building_map, rooms_and_corridors_map
    from tubejax.model.workspace.voxelmap import parse_voxel_map

    t0 = time.perf_counter()
    if spec["kind"] == "grid2d":
        decomp = parse_grid_map(rooms_and_corridors_map(spec["size"], seed=spec["seed"]), name="rooms")
        system = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
        kw = dict(zshape="box", L_max=10)
    elif spec["kind"] == "building3d":
        decomp = parse_voxel_map(building_map(spec["size"], seed=spec["seed"]), name="building")
        system = LinearSystem(A=np.eye(3), B=0.5 * np.eye(3), U=box_input_set(1.0, 3), W=Ball(3, 0.2))
        kw = dict(zshape="box", L_max=5)
    else:
        ws = yaml.safe_load((ROOT / "conf" / "workspace" / "boxgrid4d.yaml").read_text())
        cfg = yaml.safe_load((ROOT / "conf" / "system" / "double_integrator.yaml").read_text())
        decomp = box_grid(ws["lower"], ws["upper"], [int(c) for c in spec["size"]],
                          obstacles=[tuple(o) for o in ws["obstacles"]], name="boxgrid4d")
        system = LinearSystem(A=np.array(cfg["A"], float), B=np.array(cfg["B"], float),
                              U=box_input_set(cfg["U"]["bound"], 2), W=Ball(4, 0.02))
        kw = dict(zshape="cell", L_max=8)
    t_ws = time.perf_counter() - t0
    if spec["solver"] == "highs":
        from tubejax.lp.evidence.verdict import highs_solve_batch as solver
    else:
        from tubejax.lp.batch.batch_solver import PdhgBatchSolver
        opts = yaml.safe_load((ROOT / "conf" / "solver" / "pdhg.yaml").read_text())
        enable_compilation_cache(opts.pop("compilation_cache", None))
        solver = PdhgBatchSolver(**{k: v for k, v in opts.items() if k != "name"})
        if not spec.get("translation_proofs", True):   # this script's variant: every edge confirmed by a HiGHS
            solver.form = solver.form._replace(translates=False)       # solve of its own, none by translation
    if spec.get("path") == "product":
        return _product_row(decomp, system, solver, kw, spec, t0, t_ws)
    ts = build_abstraction(decomp, system, solve_batch=solver, progress=False,
                           memory_budget_mb=spec.get("memory_budget_mb"), **kw)
    s = ts.stats
    if spec.get("save_edges"):              # (src, dst, L) of every edge, to compare releases
        np.savetxt(spec["save_edges"], np.array([(e.src, e.dst, e.L) for e in ts.edges], dtype=np.int64).reshape(-1, 3),
                   fmt="%d", header="src dst L")
    sst = dict(getattr(solver, "stats", None) or {})
    solved = s["n_lps"] - s.get("n_translated", 0)
    return {
        "cells": s["n_cells"], "candidate_pairs": s["n_candidate_pairs"], "lps": solved,
        "translated": s.get("n_translated", 0),
        "edges": s["n_edges"], "lps_per_edge": solved / max(s["n_edges"], 1),
        "workspace_seconds": t_ws, "seconds_before_first_lp": s["seconds_before_first_lp"],
        "problem_seconds": s["problem_seconds"], "solve_seconds": s["solve_seconds"],
        "confirm_wait_seconds": s["confirm_wait_seconds"], "seconds": s["seconds"],
        "compile_seconds": float(sst.get("compile_seconds", 0.0)),
        "pdhg_lps_per_second": s.get("pdhg_lps_per_second"), "highs_lps_per_second": s.get("highs_lps_per_second"),
        "n_highs_solves": s.get("n_highs_solves"), "pruned": s["pruned"], "rounds": s["rounds"],
        "candidate_seconds": {k: v for k, v in s.items() if k.startswith("seconds_") and k != "seconds_before_first_lp"},
        "worker_maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "proof_seconds": float(s.get("proof", {}).get("seconds", float("nan"))),
        "n_vertex_lps": s.get("n_vertex_lps", 0), "n_vertex_duals_reused": s.get("n_vertex_duals_reused", 0),
        "n_vertex_lps_witnessed": s.get("n_vertex_lps_witnessed", 0),
        "seconds_vertex_lp": s.get("seconds_vertex_lp", 0.0),
        "status_counts": sst.get("status_counts"), "highs_cpu_seconds": sst.get("highs_cpu_seconds"),
        "decided_exactly": s.get("n_decided_exactly"), "exact_seconds": s.get("exact_decision_seconds"),
        "nonedge_evidence": s.get("nonedge_evidence"), "provenance": s.get("provenance"),
        "wall_seconds": time.perf_counter() - t0,
    }


def _product_row(decomp, system, solver, kw: dict, spec: dict, t0: float, t_ws: float) -> dict:
    """The product path (docs/math/product.md) on one workspace: its row of numbers."""
    from tubejax.abstraction.product_abstraction import build_product_abstraction

    ps = build_product_abstraction(decomp, system, solve_batch=solver, zshape=kw["zshape"], L_max=kw["L_max"])
    if spec.get("save_edges"):
        np.savetxt(spec["save_edges"], np.stack([ps.src, ps.dst, ps.L], axis=1).astype(np.int64).reshape(-1, 3),
                   fmt="%d", header="src dst L")
    s = ps.stats
    return {"cells": decomp.n_cells, "edges": s["n_edges"], "factor_cells": s["n_factor_cells"],
            "factor_lps": s["n_factor_lps"], "joint_lps": s["n_joint_lps"], "workspace_seconds": t_ws,
            "seconds": s["seconds"], "seconds_factors": s["seconds_factors"], "seconds_join": s["seconds_join"],
            "seconds_joint": s["seconds_joint"], "seconds_detect": s["seconds_detect"],
            "worker_maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "wall_seconds": time.perf_counter() - t0}


def compare_edges(joint_file: Path, product_file: Path) -> dict:
    """``joint ⊆ product`` and ``L`` never larger, from two saved edge lists (src dst L)."""
    je = {(int(a), int(b)): int(L) for a, b, L in np.loadtxt(joint_file, dtype=np.int64, ndmin=2)}
    pe = {(int(a), int(b)): int(L) for a, b, L in np.loadtxt(product_file, dtype=np.int64, ndmin=2)}
    return {"joint_edges": len(je), "product_edges": len(pe), "missing": sum(k not in pe for k in je),
            "larger_L": sum(k in pe and pe[k] > L for k, L in je.items()),
            "smaller_L": sum(k in pe and pe[k] < L for k, L in je.items())}


def product_line(name: str, joint: dict, product: dict, cmp: dict) -> str:
    """One line of the side-by-side comparison of the joint LPs and the product path."""
    return (f"| {name} | {joint['cells']} | {cmp['joint_edges']} | {cmp['product_edges']} | {cmp['missing']} | "
            f"{cmp['larger_L']} | {cmp['smaller_L']} | {joint['seconds']:.1f} | {product['seconds']:.1f} "
            f"({product['seconds_factors']:.1f} + {product['seconds_join']:.2f} + {product['seconds_joint']:.1f}) | "
            f"{joint['seconds'] / max(product['seconds'], 1e-9):.1f}x | {product['factor_lps']} |")


PRODUCT_HEADER = ("| workspace | cells | edges (joint) | edges (product) | joint edges missing | L larger | L smaller | "
                  "joint s | product s (factors + join + joint LPs) | speed-up | factor LPs |")


# -- parent -------------------------------------------------------------------------------------

def _peak_tree_rss(pid: int, stop: threading.Event, out: dict):
    """Sample the summed RSS of ``pid`` and its descendants until ``stop``; keep the largest."""
    try:
        import psutil
    except ImportError:
        return
    try:
        root = psutil.Process(pid)
        while not stop.is_set():
            procs = [root] + root.children(recursive=True)
            total = 0
            for p in procs:
                try:
                    total += p.memory_info().rss
                except psutil.Error:
                    pass
            out["peak"] = max(out.get("peak", 0), total)
            stop.wait(0.2)
    except psutil.Error:
        pass


def run_one(spec: dict, timeout: float | None) -> dict | None:
    """Run :func:`worker` in a fresh interpreter; ``None`` when it times out or fails."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", json.dumps(spec)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=str(ROOT))
    stop, mem = threading.Event(), {}
    sampler = threading.Thread(target=_peak_tree_rss, args=(proc.pid, stop, mem), daemon=True)
    sampler.start()
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        return None
    finally:
        stop.set()
        sampler.join()
    if proc.returncode != 0:
        print(f"  worker failed ({proc.returncode}):\n{err[-3000:]}", file=sys.stderr)
        return None
    row = json.loads(out.strip().splitlines()[-1])
    row["peak_rss_mb"] = mem.get("peak", 0) / 2 ** 20 or None
    return row


def median_row(rows: list) -> dict:
    """Field-wise median of the timing fields over repeats (counts are equal across repeats)."""
    out = dict(rows[0])
    for k in ("seconds", "seconds_before_first_lp", "problem_seconds", "solve_seconds", "confirm_wait_seconds",
              "pdhg_lps_per_second", "highs_lps_per_second", "peak_rss_mb", "worker_maxrss_mb", "proof_seconds",
              "wall_seconds", "exact_seconds"):
        vals = [r[k] for r in rows if r.get(k) is not None]
        out[k] = statistics.median(vals) if vals else None
    out["seconds_all"] = [r["seconds"] for r in rows]
    return out


def growth_exponent(cells, seconds, lo=1000, hi=10000):
    """Least-squares slope of log(seconds) on log(cells) over ``lo <= cells <= hi`` (None if < 2 points)."""
    pts = [(c, s) for c, s in zip(cells, seconds) if lo * 0.9 <= c <= hi * 1.1 and s]
    if len(pts) < 2:
        return None
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def _fmt(v, spec="{:.1f}"):
    return "-" if v is None else spec.format(v)


HEADER = ("| workspace | cells | cand. pairs | LPs | by class | edges | proved by translation | LPs/edge | before 1st LP s | problems s | "
          "solver s | total s | PDHG LP/s | HiGHS LP/s | PDHG decided | peak MB | HiGHS seq. s | HiGHS/PDHG | proofs after s | "
          "exact: primal / dual / solve | exact CPU s |")


def table_line(name, r, h) -> str:
    ratio = (h["seconds"] / r["seconds"]) if h else None
    return (f"| {name} | {r['cells']} | {r['candidate_pairs']} | {r['lps']} | {r.get('translated', 0)} | "
            f"{r['edges']} | {(r.get('provenance') or {}).get('exact-translate', 0)} | "
            f"{r['lps_per_edge']:.1f} | {r['seconds_before_first_lp']:.2f} | {r['problem_seconds']:.1f} | "
            f"{r['solve_seconds']:.1f} | {r['seconds']:.1f} | {_fmt(r['pdhg_lps_per_second'], '{:.0f}')} | "
            f"{_fmt(r['highs_lps_per_second'], '{:.0f}')} | {_share(r.get('status_counts'))} | "
            f"{_fmt(r['peak_rss_mb'], '{:.0f}')} | "
            f"{_fmt(h and h['seconds'])} | {_fmt(ratio, '{:.2f}')} | {_fmt(r.get('proof_seconds'))} | "
            f"{_exact_counts(r.get('decided_exactly'))} | {_fmt(r.get('exact_seconds'), '{:.2f}')} |")


def pdhg_decided(counts) -> float | None:
    """The share of PDHG's instances it decided itself (``feasible``, ``near_zero``, ``infeasible``)
    among those it ran (padding excluded); ``None`` without any."""
    if not counts:
        return None
    ran = sum(v for k, v in counts.items() if k not in ("pad", "running"))
    done = sum(counts.get(k, 0) for k in ("feasible", "near_zero", "infeasible"))
    return done / ran if ran else None


def _share(counts) -> str:
    v = pdhg_decided(counts)
    return "-" if v is None else f"{100 * v:.1f} %"


def _exact_counts(d) -> str:
    """Instances decided in exact arithmetic: by primal proof / dual certificate / exact solve."""
    if not d:
        return "-"
    return f"{d.get('primal proof', 0)} / {d.get('dual certificate', 0)} / {d.get('exact solve', 0)}"


def plot(results: list, out: Path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from matplotlib.ticker import NullFormatter

    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    for kind, marker in (("grid2d", "o"), ("boxgrid4d", "s"), ("building3d", "^")):
        rows = [r for r in results if r["kind"] == kind]
        if not rows:
            continue
        c = [r["pdhg"]["cells"] for r in rows]
        label = {"grid2d": "2-D grid", "building3d": "3-D building"}.get(kind, "4-D double integrator")
        for key, color, ls, what in (("seconds", "C0", "-", "total (PDHG)"), ("solve_seconds", "C1", "--", "solver"),
                                     ("seconds_before_first_lp", "C2", ":", "before 1st LP")):
            ax.loglog(c, [r["pdhg"][key] for r in rows], marker=marker, color=color, ls=ls, label=f"{label}: {what}")
        hs = [(r["pdhg"]["cells"], r["highs"]["seconds"]) for r in rows if r.get("highs")]
        if hs:
            ax.loglog(*zip(*hs), marker=marker, color="C3", ls="none", mfc="none",
                      label=f"{label}: sequential HiGHS")
    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.set_xlabel("cells")
    ax.set_ylabel("seconds")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    for ext in ("png", "pdf"):
        fig.savefig(out / f"scaling.{ext}")


def drone_rows(specs: str, out: Path) -> None:
    """Run experiments/drone_scale.py on each ``MAP:DIVISIONS`` (fresh processes) and keep its rows."""
    lines = []
    for spec in filter(None, (x.strip() for x in specs.split(";"))):
        map_file, _, div = spec.rpartition(":")
        res = subprocess.run([sys.executable, str(ROOT / "experiments" / "drone_scale.py"), map_file, div],
                             stdout=subprocess.PIPE, text=True, cwd=ROOT)
        got = [x for x in res.stdout.splitlines() if x.startswith("|")]
        lines += got if not lines else got[2:]
        print("\n".join(got), flush=True)
    (out / "drone.md").write_text("\n".join(lines) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default=",".join(map(str, SIZES)), help="2-D free-cell counts (comma-separated; '' for none)")
    ap.add_argument("--divisions", default=",".join(DIVISIONS), help="4-D grids, e.g. 4444,5555 ('' for none)")
    ap.add_argument("--buildings", default="", help="3-D buildings, free voxels (comma-separated), e.g. 2000,20000")
    ap.add_argument("--max-cells", type=int, default=10000, help="skip workspaces with more cells")
    ap.add_argument("--no-highs", action="store_true", help="skip the sequential HiGHS runs")
    ap.add_argument("--highs-timeout", type=float, default=300.0, help="give up a HiGHS run after this (s)")
    ap.add_argument("--out", default="outputs/scaling", help="output directory (git-ignored by default)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the generated maps")
    ap.add_argument("--repeats", type=int, default=1, help="PDHG runs per size (median reported)")
    ap.add_argument("--memory-budget-mb", type=int, default=None,
                    help="memory_budget_mb of the rounds (the apps' default is 2048; default here: none)")
    ap.add_argument("--no-translation-proofs", action="store_true",
                    help="confirm every edge with a HiGHS solve of its own (no proofs by exact translation, "
                         "tubejax.lp.evidence.translate_verdicts)")
    ap.add_argument("--save-edges", action="store_true",
                    help="write each size's edges (src dst L) to OUT/edges_<name>.txt, to compare releases")
    ap.add_argument("--product", action="store_true",
                    help="also run the product path (docs/math/product.md) on the 4-D grids with the same solver, "
                         "and print its edges and time beside the joint LPs' (OUT/product.md)")
    ap.add_argument("--drone", default="",
                    help="6-D drone product path on lifted voxel maps, phase by phase (experiments/drone_scale.py), "
                         "e.g. conf/workspace/maps/building3d.txt:10,8,5 (';'-separated); rows in OUT/drone.md")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(json.loads(args.worker))))
        return
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.drone:
        drone_rows(args.drone, out)
    jobs = [("grid2d", int(s)) for s in args.sizes.split(",") if s.strip()]
    jobs += [("boxgrid4d", d.strip()) for d in args.divisions.split(",") if d.strip()]
    jobs += [("building3d", int(b)) for b in args.buildings.split(",") if b.strip()]
    results, highs_ok = [], {"grid2d": True, "boxgrid4d": True, "building3d": True}
    print(HEADER)
    print("|" + "---|" * (HEADER.count("|") - 1))
    for n, (kind, size) in enumerate(jobs, 1):
        cells = _four_d_cells(size) if kind == "boxgrid4d" else size
        name = (f"rooms ~{size}" if kind == "grid2d" else f"3-D building ~{size}" if kind == "building3d"
                else f"4-D {'x'.join(size)}")
        if cells > args.max_cells * 1.1:
            print(f"[{n}/{len(jobs)}] {name}: {cells} cells > --max-cells, skipped", file=sys.stderr)
            continue
        spec = {"kind": kind, "size": size, "seed": args.seed, "solver": "pdhg",
                "memory_budget_mb": args.memory_budget_mb,
                "translation_proofs": not args.no_translation_proofs,
                "save_edges": str(out.resolve() / f"edges_{kind}_{size}.txt")
                if args.save_edges or (args.product and kind == "boxgrid4d") else None}
        rows = []
        for rep in range(max(1, args.repeats)):
            print(f"[{n}/{len(jobs)}] {name}: PDHG run {rep + 1}/{args.repeats} ...", file=sys.stderr, flush=True)
            r = run_one(spec, None)
            if r is not None:
                rows.append(r)
        if not rows:
            continue
        row = {"kind": kind, "size": size, "name": name, "pdhg": median_row(rows)}
        if not args.no_highs and highs_ok[kind]:
            print(f"[{n}/{len(jobs)}] {name}: sequential HiGHS ...", file=sys.stderr, flush=True)
            row["highs"] = run_one(dict(spec, solver="highs"), args.highs_timeout)
            highs_ok[kind] = row["highs"] is not None             # larger sizes would take longer still
        if args.product and kind == "boxgrid4d":
            print(f"[{n}/{len(jobs)}] {name}: product path ...", file=sys.stderr, flush=True)
            pfile = out.resolve() / f"edges_product_{kind}_{size}.txt"
            row["product"] = run_one(dict(spec, path="product", save_edges=str(pfile)), None)
            if row["product"] is not None:
                row["product_compare"] = compare_edges(Path(spec["save_edges"]), pfile)
        results.append(row)
        print(table_line(name, row["pdhg"], row.get("highs")), flush=True)
        (out / "results.json").write_text(json.dumps({"rows": results}, indent=1))
    fits = {}
    for kind in ("grid2d", "boxgrid4d", "building3d"):
        rows = [r["pdhg"] for r in results if r["kind"] == kind]
        lo, hi = FIT_RANGE.get(kind, (1000, 10000))
        fits[kind] = {k: growth_exponent([r["cells"] for r in rows], [r[k] for r in rows], lo, hi)
                      for k in ("seconds", "seconds_before_first_lp", "solve_seconds")}
    for kind, f in fits.items():
        if f["seconds"] is not None:
            lo, hi = FIT_RANGE.get(kind, (1000, 10000))
            print(f"{kind}: time ∝ cells^{f['seconds']:.2f} ({lo:,}..{hi:,} cells); before the first LP "
                  f"∝ cells^{_fmt(f['seconds_before_first_lp'], '{:.2f}')}, solver ∝ cells^"
                  f"{_fmt(f['solve_seconds'], '{:.2f}')}")
    (out / "results.json").write_text(json.dumps({"rows": results, "growth_exponents": fits}, indent=1))
    lines = [HEADER, "|" + "---|" * (HEADER.count("|") - 1)]
    lines += [table_line(r["name"], r["pdhg"], r.get("highs")) for r in results]
    (out / "table.md").write_text("\n".join(lines) + "\n")
    prod = [r for r in results if r.get("product_compare")]
    if prod:
        lines = [PRODUCT_HEADER, "|" + "---|" * (PRODUCT_HEADER.count("|") - 1)]
        lines += [product_line(r["name"], r["pdhg"], r["product"], r["product_compare"]) for r in prod]
        (out / "product.md").write_text("\n".join(lines) + "\n")
        print("\n".join(lines))
    if results:
        plot(results, out)
        print(f"wrote {out / 'scaling.png'}, {out / 'scaling.pdf'}, {out / 'table.md'}, {out / 'results.json'}")


if __name__ == "__main__":
    main()
