"""Benchmark: the 6-D drone's product path on a lifted building, phase by phase (a script, not a test).

Lifts a voxel map by velocity divisions (docs/math/drone.md), detects the product structure, solves
the factor LPs (HiGHS, ``L_max`` 8, both safe-set variants, pruning on), joins them
(:func:`tubejax.abstraction.product_join.join_factors`) and, with ``--joint``, solves the joint LPs of
the pairs whose bounding box meets an obstacle while their hull does not (``--joint-sample N``: only
``N`` of them, drawn at random with seed 0, and the time for all of them extrapolated; ``--profile``:
the joint phase under cProfile, its 25 costliest calls by cumulative time on stderr), each first
tried against its projections on pairs of axis groups (:mod:`tubejax.abstraction.joint_projections`;
``--no-projections``: without them, as before; ``--edges FILE``: the joint edges as JSON, to compare
the two). Prints one
Markdown row: cells, factor LPs, pairs tested, edges, joint pairs, seconds per phase, peak RSS
(``ru_maxrss``) and the load average at the end (the machine may be shared), then with ``--joint`` a
line on the joint phase: pairs solved, pair horizons refuted by projections and the projected LPs
that did it, joint LPs (and how many of them an earlier LP's dual refuted,
:class:`~tubejax.abstraction.joint_duals.DualReuseSolver`), joint edges, seconds.

Its figures, with the commands that gave them, are in docs/math/drone.md (results).

Usage
-----
python experiments/drone_scale.py conf/workspace/maps/building3d.txt 10,8,5
python experiments/drone_scale.py conf/workspace/maps/building3d_small.txt 5,4,5 --joint-sample 200 --profile
python experiments/scaling.py --sizes '' --divisions '' --drone conf/workspace/maps/building3d.txt:10,8,5
"""

from __future__ import annotations

import argparse
import cProfile
import json
import dataclasses
import os
import pstats
import resource
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from tqdm.auto import tqdm  # noqa: E402

from tubejax.abstraction.joint_projections import ProjectionScreen  # noqa: E402
from tubejax.abstraction.product_joint_lps import joint_pairs, joint_solver  # noqa: E402
from tubejax.abstraction.product_factors import solve_factor  # noqa: E402
from tubejax.abstraction.product_join import join_factors  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.model.product_structure import product_structure  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.system_kinds import double_integrator_lookahead  # noqa: E402
from tubejax.model.workspace.lookahead import lift_lookahead  # noqa: E402
from tubejax.model.workspace.voxelmap import parse_map  # noqa: E402
from tubejax.model.zshape.kinds import cross_sections  # noqa: E402

HEADER = ("| map | divisions | cells | factor LPs | pairs tested | edges | joint pairs | lift s | structure s | "
          "factor LPs s | join s | joint LPs s | peak RSS MB | load |")


def run(map_file: str, divisions: list, L_max: int = 8, joint: bool = False, memory_mb: float = 256.0,
        joint_sample: int = 0, profile: bool = False, projections: bool = True) -> dict:
    """The phases on one lifted map (conf/system/drone6d.yaml: dt 0.5, beta 2, |a| <= 1, W a 0.01 ball).

    ``joint_sample > 0``: the joint LPs of only that many pairs (seed 0); ``profile``: the joint phase
    under cProfile (its 25 costliest calls on stderr); ``projections=False``: without the projection
    screen (:mod:`tubejax.abstraction.joint_projections`), as before it.
    """
    t = [time.perf_counter()]
    decomp = lift_lookahead(parse_map(Path(map_file).read_text(), map_file), divisions)
    t.append(time.perf_counter())
    A, B = double_integrator_lookahead(3, 0.5, 2.0)
    system = LinearSystem(A=A.astype(float), B=B.astype(float), U=box_input_set(1.0, 3), W=Ball(6, 0.01))
    Zs = cross_sections(decomp, "cell", 1.0)
    structure = product_structure(decomp, system, Zs)
    t.append(time.perf_counter())
    tables = [solve_factor(f, g, L_max, progress=True) for g, f in enumerate(structure.factors)]
    t.append(time.perf_counter())
    with tqdm(total=decomp.n_cells, desc="join", unit="cell") as bar:
        joined = join_factors(decomp, structure, tables, memory_mb, bar)
    t.append(time.perf_counter())
    n_all = len(joined.joint_src)
    solved = {"pairs": 0, "lps": 0, "edges": 0, "reused": 0, "projection_lps": 0, "projected": 0}
    if joint:
        if 0 < joint_sample < n_all:
            k = np.sort(np.random.default_rng(0).choice(n_all, joint_sample, replace=False))
            joined = dataclasses.replace(joined, joint_src=joined.joint_src[k], joint_dst=joined.joint_dst[k],
                                         joint_box_mask=joined.joint_box_mask[k])
        prof = cProfile.Profile() if profile else None
        t[-1] = time.perf_counter()
        if prof is not None:
            prof.enable()
        solver = joint_solver(None)
        screen = ProjectionScreen(structure, system) if projections else None
        _, L_of, margin_of, n_lps = joint_pairs(decomp, system, Zs, joined, L_max, 0.0, solver, screen)
        if prof is not None:
            prof.disable()
            pstats.Stats(prof, stream=sys.stderr).sort_stats("cumulative").print_stats(25)
        solved = {"pairs": len(joined.joint_src), "lps": n_lps, "edges": len(L_of),
                  "reused": getattr(solver, "n_reused", 0), "translated": getattr(solver, "n_translated", 0),
                  "projection_lps": screen.n_lps if screen else 0,
                  "projected": screen.n_refuted if screen else 0,
                  "joint_edge_list": sorted((i, j, L, margin_of[(i, j)]) for (i, j), L in L_of.items())}
    t.append(time.perf_counter())
    return {"map": Path(map_file).stem, "divisions": list(divisions), "cells": decomp.n_cells,
            "factor_lps": sum(tb.n_lps for tb in tables), "tested": joined.n_box_tested, "edges": len(joined.src),
            "joint_pairs": n_all, "joint_solved_pairs": solved["pairs"], "joint_lps": solved["lps"],
            "joint_reused": solved["reused"], "joint_translated": solved.get("translated", 0),
            "joint_edges": solved["edges"],
            "projection_lps": solved["projection_lps"], "joint_projected": solved["projected"],
            "joint_edge_list": solved.get("joint_edge_list", []),
            "seconds": [b - a for a, b in zip(t, t[1:])],
            "joint_solved": joint, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "load": os.getloadavg()[0]}


def row(r: dict) -> str:
    """The row of :data:`HEADER`."""
    s = [f"{x:.0f}" for x in r["seconds"]]
    s[-1] = s[-1] if r["joint_solved"] else "not run"
    return (f"| {r['map']} | {'x'.join(map(str, r['divisions']))} | {r['cells']:,} | {r['factor_lps']:,} | "
            f"{r['tested']:,} | {r['edges']:,} | {r['joint_pairs']:,} | {' | '.join(s)} | "
            f"{r['peak_rss_mb']:,.0f} | {r['load']:.1f} |")


def joint_line(r: dict) -> str:
    """The joint phase in words: pairs, LPs, LPs refuted by reused duals, edges, seconds (for a sample also
    extrapolated to all pairs)."""
    s, n, m = r["seconds"][-1], r["joint_solved_pairs"], r["joint_pairs"]
    line = (f"joint phase: {n:,} of {m:,} pairs, {r['joint_projected']:,} pair horizons refuted by "
            f"{r['projection_lps']:,} projected LPs, {r['joint_lps']:,} joint LPs ({r['joint_reused']:,} refuted by an "
            f"earlier LP's dual, {r['joint_translated']:,} edges proved by their class's representative translated), "
            f"{r['joint_edges']:,} joint edges, {s:.0f} s")
    if 0 < n < m:
        line += f"; all {m:,} pairs at this rate: {s * m / n / 3600:.1f} h"
    return line


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("map_file")
    ap.add_argument("divisions", help="velocity divisions per axis, e.g. 10,8,5")
    ap.add_argument("--L-max", type=int, default=8)
    ap.add_argument("--joint", action="store_true",
                    help="also solve the joint LPs (HiGHS one by one, reusing refuting duals)")
    ap.add_argument("--memory-mb", type=float, default=256.0, help="the join's block budget")
    ap.add_argument("--joint-sample", type=int, default=0,
                    help="> 0: solve the joint LPs of only that many pairs (seed 0; implies --joint)")
    ap.add_argument("--profile", action="store_true", help="profile the joint phase (cProfile, on stderr)")
    ap.add_argument("--no-projections", action="store_true",
                    help="solve every joint LP, without refuting any by its projections (as before them)")
    ap.add_argument("--edges", default="", help="write the joint edges (i, j, L, margin) to this JSON file")
    args = ap.parse_args(argv)
    joint = args.joint or args.joint_sample > 0
    r = run(args.map_file, [int(x) for x in args.divisions.split(",")], args.L_max, joint, args.memory_mb,
            args.joint_sample, args.profile, not args.no_projections)
    if args.edges:
        Path(args.edges).write_text(json.dumps(r["joint_edge_list"]))
    print(HEADER)
    print("|" + "---|" * (HEADER.count("|") - 1))
    print(row(r), flush=True)
    if joint:
        print(joint_line(r), flush=True)
    return r


if __name__ == "__main__":
    main()
