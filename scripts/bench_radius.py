"""Benchmark: rho* of every candidate (pair, L) of a map (the radius form, one batched solve)
against one margin-form abstraction at a single radius, in one run.

Candidates are the (pair, L) that ``tubejax.abstraction.candidates.build_candidates`` keeps at ``rho = 0``
(``W = {0}``: sound for every radius). Both sides run once to compile, then ``--repeats``
times alternately (compile excluded); the ratio is the median of the per-repeat ratios.
The issue's target (issue 12): the full radius curve costs <= 2x one abstraction.

Usage
-----
python scripts/bench_radius.py                         # paper map, r = 0.2, L_max = 10, tube
python scripts/bench_radius.py --gap-tol 1e-6 --repeats 5
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections import Counter

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.lp.batch.batch_solver import RADIUS_OPTIONS, pdhg_solver  # noqa: E402
from tubejax.model.zshape.kinds import make_z  # noqa: E402
from tubejax.model.problem import pair_problem  # noqa: E402
from tubejax.analyses.zshape.learn import candidate_pairs  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace import load_grid_map  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--map", default="conf/workspace/maps/paper.txt")
    ap.add_argument("--radius", type=float, default=0.2)
    ap.add_argument("--L-max", type=int, default=10)
    ap.add_argument("--form", choices=("tube", "openloop"), default="tube")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--gap-tol", type=float, default=RADIUS_OPTIONS.gap_tol)
    a = ap.parse_args()

    dec = load_grid_map(a.map)
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, a.radius))
    sys0 = LinearSystem(A=sysm.A, B=sysm.B, U=sysm.U, W=Ball(2, 0.0))
    _, keep = candidate_pairs(dec, sys0, a.L_max)
    Z = [make_z("box", c) for c in dec.cells]
    cands = np.argwhere(keep)
    probs = [pair_problem(dec, sysm, Z[i], int(i), int(j), int(L) + 1) for i, j, L in cands]

    margin = pdhg_solver(a.form)
    radius = pdhg_solver(a.form, radius=True, gap_tol=a.gap_tol)

    def run_margin():
        margin.reset_stats()
        t0 = time.perf_counter()
        ts = build_abstraction(dec, sysm, L_max=a.L_max, solve_batch=margin, progress=False,
                               method=a.form)
        return time.perf_counter() - t0, ts

    def run_radius():
        radius.reset_stats()
        t0 = time.perf_counter()
        res = radius.optimise(probs)
        return time.perf_counter() - t0, res

    t_m0, ts = run_margin()
    t_r0, res = run_radius()
    print(f"{a.map}: {dec.n_cells} cells, {len(probs)} candidate (pair, L), form {a.form}, "
          f"margin abstraction at r = {a.radius}: {ts.stats['n_lps']} LPs, {ts.stats['n_edges']} edges")
    print(f"first runs (compiling): margin {t_m0:.2f} s (compile {margin.stats['compile_seconds']:.2f} s), "
          f"radius {t_r0:.2f} s (compile {radius.stats['compile_seconds']:.2f} s)")
    tm, tr = [], []
    for _ in range(a.repeats):
        tm.append(run_margin()[0])
        dt, res = run_radius()
        tr.append(dt)
    ratio = statistics.median(r / m for r, m in zip(tr, tm))
    its = np.asarray(res.iterations)
    st = Counter(res.status)
    n_edge = int(np.sum(np.asarray(res.lower) >= a.radius))
    print(f"margin abstraction: {', '.join(f'{t:.2f}' for t in tm)} s (median {statistics.median(tm):.2f})")
    print(f"rho* of every candidate: {', '.join(f'{t:.2f}' for t in tr)} s (median {statistics.median(tr):.2f})")
    print(f"ratio radius / margin (median of per-repeat ratios): {ratio:.2f}")
    print(f"rho* statuses: {dict(st)}; iterations median {np.median(its):.0f}, p99 "
          f"{np.percentile(its, 99):.0f}, max {its.max()}; gap_tol {a.gap_tol:g}; "
          f"candidates with lower >= {a.radius}: {n_edge}")
    ms, rs = margin.stats, radius.stats
    print(f"margin: iterations median {ms['iterations_median']:.0f}, "
          f"HiGHS solves {ms['sent_to_highs'] + ms['highs_confirmations']}")
    for name, s in (("margin", ms), ("radius", rs)):
        print(f"{name}: slot iterations {s['slot_iterations']}, device {s['device_seconds']:.2f} s "
              f"({1e6 * s['device_seconds'] / max(s['slot_iterations'], 1):.2f} us per LP-iteration), "
              f"pdhg {s['pdhg_seconds']:.2f} s, calls {s['calls']}")


if __name__ == "__main__":
    main()
