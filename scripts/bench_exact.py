"""Cost of the exact proofs (docs/math/evidence.md#proof-levels) on a grid map.

    python scripts/bench_exact.py                       # the paper map, r = 0.2, L_max = 10
    python scripts/bench_exact.py --map corridor --radius 0.2

Prints, for one HiGHS abstraction: its CPU time and the part spent proving tubes
inside the edge confirmations (exact check, snapping, basis rebuild), the safe-set
proofs, the proof levels and routes, then the cost of the exact checker alone, of
re-proving HiGHS's raw tubes from scratch (an old file), and of ``verify()``.
CPU times (``time.process_time``): the machine may be shared.
"""

from __future__ import annotations

import argparse
import time
from collections import Counter
from pathlib import Path

import numpy as np

import tubejax.lp.evidence.verdict as verdict_module
from tubejax.abstraction import build_abstraction
from tubejax.model.geometry import Ball
from tubejax.lp.evidence import exact_tube_violation, prove_evidence
from tubejax.lp.declarations.tube_lp import build_tube_lp
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import load_grid_map

MAPS = Path(__file__).resolve().parents[1] / "conf" / "workspace" / "maps"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--map", default="paper")
    ap.add_argument("--radius", type=float, default=0.2)
    ap.add_argument("--L-max", type=int, default=10)
    args = ap.parse_args()

    spent = {"s": 0.0, "n": 0, "routes": Counter()}
    original = verdict_module._prove

    def timed(*a, **k):
        t = time.process_time()
        out = original(*a, **k)
        spent["s"] += time.process_time() - t
        spent["n"] += 1
        spent["routes"][(out[1].level, out[1].note.split(";")[0])] += 1
        return out

    verdict_module._prove = timed
    system = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, args.radius))
    decomp = load_grid_map(MAPS / f"{args.map}.txt")
    t0 = time.process_time()
    ts = build_abstraction(decomp, system, L_max=args.L_max, progress=False)
    total = time.process_time() - t0
    verdict_module._prove = original
    n = ts.n_edges
    print(f"{args.map}: {decomp.n_cells} cells, {n} edges ({ts.stats['n_zero_margin']} with |t*| <= 1e-9), "
          f"r = {args.radius}, L_max = {args.L_max}")
    print(f"abstraction CPU {total:.2f} s; tube proofs in the confirmations {spent['s']:.3f} s "
          f"({1e3 * spent['s'] / max(spent['n'], 1):.2f} ms/edge, {100 * spent['s'] / total:.0f} %); "
          f"safe sets {ts.stats['proof']['seconds']:.3f} s")
    print("levels:", {k: v for k, v in ts.stats["proof"].items() if k != "seconds"})
    for (level, how), c in sorted(spent["routes"].items()):
        print(f"  {c:4d} x {level}: {how}")

    probs = [ts.problem(k) for k in range(n)]
    evidence = [e.exact if e.exact is not None else ts.tubes[k] for k, e in enumerate(ts.edges)]
    t0 = time.process_time()
    worst = max(exact_tube_violation(p, ev) for p, ev in zip(probs, evidence))
    dt = time.process_time() - t0
    print(f"exact check of the stored evidence: {1e3 * dt / n:.2f} ms/edge (max exact violation {float(worst):.1e})")

    raw = [build_tube_lp(p).index.split(solve_margin_lp(build_tube_lp(p)).x) for p in probs]
    t0 = time.process_time()
    levels = Counter(prove_evidence(p, tube).level for p, tube in zip(probs, raw))
    dt = time.process_time() - t0
    print(f"re-proving HiGHS's raw tubes (as for an old file, re-solving where needed): "
          f"{1e3 * dt / n:.2f} ms/edge, levels {dict(levels)}")
    t0 = time.process_time()
    ts.verify()
    print(f"verify() (float re-check + exact re-proof + safe sets): {time.process_time() - t0:.2f} s")


if __name__ == "__main__":
    main()
