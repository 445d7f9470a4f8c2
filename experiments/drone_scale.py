"""Benchmark: the 6-D drone's product path on a lifted building, phase by phase (a script, not a test).

Lifts a voxel map by velocity divisions (docs/math/drone.md), detects the product structure, solves
the factor LPs (HiGHS, ``L_max`` 8, both safe-set variants, pruning on), joins them
(:func:`tubejax.abstraction.product_join.join_factors`) and, with ``--joint``, solves the joint LPs of
the pairs whose bounding box meets an obstacle while their hull does not. Prints one Markdown row:
cells, factor LPs, pairs tested, edges, joint pairs, seconds per phase, peak RSS (``ru_maxrss``) and
the load average at the end (the machine may be shared).

Usage
-----
python experiments/drone_scale.py conf/workspace/maps/building3d.txt 10,8,5
python experiments/scaling.py --sizes '' --divisions '' --drone conf/workspace/maps/building3d.txt:10,8,5
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tqdm.auto import tqdm  # noqa: E402

from tubejax.abstraction.product_abstraction import _joint_pairs, _joint_solver  # noqa: E402
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


def run(map_file: str, divisions: list, L_max: int = 8, joint: bool = False, memory_mb: float = 256.0) -> dict:
    """The phases on one lifted map (conf/system/drone6d.yaml: dt 0.5, beta 2, |a| <= 1, W a 0.01 ball)."""
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
    if joint:
        _joint_pairs(decomp, system, Zs, joined, L_max, 0.0, _joint_solver(None, None, len(joined.joint_src)))
    t.append(time.perf_counter())
    return {"map": Path(map_file).stem, "divisions": list(divisions), "cells": decomp.n_cells,
            "factor_lps": sum(tb.n_lps for tb in tables), "tested": joined.n_box_tested, "edges": len(joined.src),
            "joint_pairs": len(joined.joint_src), "seconds": [b - a for a, b in zip(t, t[1:])],
            "joint_solved": joint, "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
            "load": os.getloadavg()[0]}


def row(r: dict) -> str:
    """The row of :data:`HEADER`."""
    s = [f"{x:.0f}" for x in r["seconds"]]
    s[-1] = s[-1] if r["joint_solved"] else "not run"
    return (f"| {r['map']} | {'x'.join(map(str, r['divisions']))} | {r['cells']:,} | {r['factor_lps']:,} | "
            f"{r['tested']:,} | {r['edges']:,} | {r['joint_pairs']:,} | {' | '.join(s)} | "
            f"{r['peak_rss_mb']:,.0f} | {r['load']:.1f} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("map_file")
    ap.add_argument("divisions", help="velocity divisions per axis, e.g. 10,8,5")
    ap.add_argument("--L-max", type=int, default=8)
    ap.add_argument("--joint", action="store_true", help="also solve the joint LPs (HiGHS, one by one)")
    ap.add_argument("--memory-mb", type=float, default=256.0, help="the join's block budget")
    args = ap.parse_args(argv)
    r = run(args.map_file, [int(x) for x in args.divisions.split(",")], args.L_max, args.joint, args.memory_mb)
    print(HEADER)
    print("|" + "---|" * (HEADER.count("|") - 1))
    print(row(r), flush=True)
    return r


if __name__ == "__main__":
    main()
