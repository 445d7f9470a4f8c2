"""Dense against sparse margin rows, side by side: building the tube LPs and HiGHS's pass + solve.

Runs this file as a worker under two checkouts in turn (``--old``: the dense path, e.g. the main
checkout; ``--new``: this one), alternating, each run in a fresh process with the row caches
empty, and prints per case the medians of ``--runs`` runs (seconds for all of the case's LPs) and
the load average. The cases: 12 joint 6-D drone LPs at ``L = 8`` (building3d_small lifted with
2 look-ahead slabs per axis, pairs of touching cells drawn with seed 0), the paper map (2-D,
``L = 10``) and the 4-D double integrator (``L = 8``). Both checkouts must give the same statuses
and margins, bit for bit (checked).

Usage::

    python scripts/bench_sparse_rows.py --old /work/main --new .
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _cases():
    import numpy as np

    from tubejax.model.geometry import Ball
    from tubejax.model.problem import Pairs, pair_problems
    from tubejax.model.system import LinearSystem, box_input_set
    from tubejax.model.system_kinds import double_integrator_lookahead
    from tubejax.model.workspace import box_grid, load_grid_map
    from tubejax.model.workspace.lookahead import lift_lookahead
    from tubejax.model.workspace.voxelmap import parse_map
    from tubejax.model.zshape.kinds import cross_sections

    def touching(decomp, k, seed):
        lo, hi = decomp.cell_boxes()
        rng = np.random.default_rng(seed)
        src, dst = [], []
        while len(src) < k:
            i = int(rng.integers(decomp.n_cells))
            near = np.flatnonzero(np.all((lo <= hi[i] + 1e-9) & (hi >= lo[i] - 1e-9), axis=1))
            near = near[near != i]
            if near.size:
                src.append(i)
                dst.append(int(rng.choice(near)))
        return Pairs(np.array(src), np.array(dst), np.zeros(k, bool))

    mf = ROOT / "conf" / "workspace" / "maps" / "building3d_small.txt"
    drone = lift_lookahead(parse_map(mf.read_text(), str(mf)), [2, 2, 2])
    A, B = double_integrator_lookahead(3, 0.5, 2.0)
    s6 = LinearSystem(A=A.astype(float), B=B.astype(float), U=box_input_set(1.0, 3), W=Ball(6, 0.01))
    paper = load_grid_map(ROOT / "conf" / "workspace" / "maps" / "paper.txt")
    s2 = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    grid4 = box_grid([0.0] * 4, [3.0, 2.0, 3.0, 2.0], [3, 2, 3, 2],
                     obstacles=[([1.0, 0.0, 1.0, 0.0], [2.0, 2.0, 2.0, 2.0])])
    A4 = np.array([[0.75, 0.25, 0, 0], [-0.25, 1.25, 0, 0], [0, 0, 0.75, 0.25], [0, 0, -0.25, 1.25]])
    B4 = np.array([[0.125, 0], [1.125, 0], [0, 0.125], [0, 1.125]])
    s4 = LinearSystem(A=A4, B=B4, U=box_input_set(1.0, 2), W=Ball(4, 0.02))
    def case(decomp, system, zshape, k, seed, L):
        return pair_problems(decomp, system, cross_sections(decomp, zshape, 1.0), touching(decomp, k, seed), L)

    return {"drone-6d L=8 (12 LPs)": case(drone, s6, "cell", 12, 0, 8),
            "paper-2d L=10 (300 LPs)": case(paper, s2, "box", 300, 1, 10),
            "double-integrator-4d L=8 (100 LPs)": case(grid4, s4, "cell", 100, 2, 8)}


def worker() -> dict:
    """One run of every case in this process (row caches emptied first): seconds and results."""
    from tubejax.lp.declarations import tube_lp
    from tubejax.lp.declarations.tube_lp import build_tube_lp
    from tubejax.lp.engines.highs import solve_margin_lp

    out = {}
    for name, probs in _cases().items():
        for cache in (v for k, v in vars(tube_lp).items() if k.endswith("_CACHE") and isinstance(v, dict)):
            cache.clear()
        for used in tube_lp._CACHE_USED.values():
            used[0] = 0
        t0 = time.perf_counter()
        lps = [build_tube_lp(p) for p in probs]
        t1 = time.perf_counter()
        res = [solve_margin_lp(lp) for lp in lps]
        t2 = time.perf_counter()
        out[name] = {"build": t1 - t0, "solve": t2 - t1, "results": [(r.status, repr(r.margin)) for r in res],
                     "module": tube_lp.__file__}
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", default="/work/main", help="checkout with the dense path")
    ap.add_argument("--new", default=str(ROOT), help="checkout with the sparse path")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print(json.dumps(worker()))
        return
    runs = {"old": [], "new": []}
    for _ in range(args.runs):
        for tag in ("old", "new"):
            env = dict(os.environ, PYTHONPATH=str(Path(getattr(args, tag)).resolve()))
            p = subprocess.run([sys.executable, __file__, "--worker"], env=env, capture_output=True, text=True,
                               check=True)
            runs[tag].append(json.loads(p.stdout.strip().splitlines()[-1]))
    print(f"load average before/after: {os.getloadavg()}")
    print("| case | build old s | build new s | pass+solve old s | pass+solve new s | same results |")
    print("|---|---|---|---|---|---|")
    for name in runs["old"][0]:
        med = {(t, k): statistics.median(r[name][k] for r in runs[t]) for t in runs for k in ("build", "solve")}
        same = all(r[name]["results"] == runs["old"][0][name]["results"] for t in runs for r in runs[t])
        print(f"| {name} | {med['old', 'build']:.2f} | {med['new', 'build']:.2f} | {med['old', 'solve']:.2f} | "
              f"{med['new', 'solve']:.2f} | {same} |")
    print("modules:", runs["old"][0][name]["module"], runs["new"][0][name]["module"])


if __name__ == "__main__":
    main()
