"""Benchmark (issue 12's target): the full radius curve of a map from one solve against one
single-radius abstraction and a 7-point sweep, side by side in one run.

Each repeat runs, in this order and with every executable compiled beforehand (compile excluded):

(a) one abstraction at ``--radius`` (Algorithm 2, the batched engine, HiGHS confirmations and exact
    proofs: what ``experiments/abstract.py`` runs);
(b) the curve: ``rho*`` of every candidate (pair, ``L <= L_max``) by the batched engine
    (:func:`tubejax.analyses.radius_analysis.solve_radius_table`): ``n_edges(rho)`` to within the engine's
    gap (a certified bracket per pair);
(c) the exact curve: (b) plus HiGHS on every instance that may attain a pair's maximum
    (:meth:`RadiusTable.refine`, half of the solves in the HiGHS helper process);
(d) the 7-point sweep: 7 abstractions as (a) at the radii ``0, 0.05, ..., 0.3``, in one process
    (a Hydra sweep also pays 7 start-ups and compiles);
(e) the 7 verified systems derived from (c) (:func:`transition_system_at`), checked identical
    (edges and ``L``) to (d)'s.

Ratios are medians of the per-repeat ratios. Usage::

    python scripts/bench_radius_curve.py                      # paper map, tube, 3 repeats
    python scripts/bench_radius_curve.py --form openloop --repeats 5
"""

from __future__ import annotations

import argparse
import statistics
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from tubejax.abstraction import build_abstraction, cross_sections  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.lp.batch.batch_solver import pdhg_solver  # noqa: E402
from tubejax.lp.engines.workers import shared_process_workers  # noqa: E402
from tubejax.analyses.radius_analysis import RadiusTableOptions, solve_radius_table, transition_system_at  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace import load_grid_map  # noqa: E402

SWEEP = (0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--map", default="conf/workspace/maps/paper.txt")
    ap.add_argument("--radius", type=float, default=0.2)
    ap.add_argument("--L-max", type=int, default=10)
    ap.add_argument("--form", choices=("tube", "openloop"), default="tube")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--no-sweep", action="store_true", help="skip (d) and (e)")
    a = ap.parse_args()

    dec = load_grid_map(a.map)
    systems = {r: LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, r))
               for r in sorted(set(SWEEP) | {a.radius})}
    Z = cross_sections(dec, "box", 1.0)
    margin = pdhg_solver(a.form)
    radius = pdhg_solver(a.form, radius=True)
    workers = shared_process_workers()

    def abstraction(r):
        c0 = margin.stats["compile_seconds"]
        t0 = time.perf_counter()
        ts = build_abstraction(dec, systems[r], L_max=a.L_max, solve_batch=margin, progress=False, method=a.form)
        return time.perf_counter() - t0 - (margin.stats["compile_seconds"] - c0), ts

    def curve():
        table = solve_radius_table(dec, systems[a.radius], Z=Z, options=RadiusTableOptions(form=a.form, L_max=a.L_max),
                                   solver=radius, workers=workers)
        t0 = time.perf_counter()
        table.refine(workers=workers)
        return table.stats["seconds"], time.perf_counter() - t0, table

    t_first = time.perf_counter()
    abstraction(a.radius)
    curve()
    print(f"{a.map}: {dec.n_cells} cells, form {a.form}, L_max {a.L_max}; warm-up (compiling) "
          f"{time.perf_counter() - t_first:.1f} s")
    rows = []
    for rep in range(a.repeats):
        t_a, ts = abstraction(a.radius)
        t_b, t_ref, table = curve()
        row = {"a": t_a, "b": t_b, "c": t_b + t_ref}
        if not a.no_sweep:
            sweep = {r: abstraction(r) for r in SWEEP}
            row["d"] = sum(t for t, _ in sweep.values())
            t0 = time.perf_counter()
            derived = {r: transition_system_at(table, r, workers=workers) for r in SWEEP}
            row["e"] = time.perf_counter() - t0
            same = all({(e.src, e.dst): e.L for e in derived[r].edges} == {(e.src, e.dst): e.L for e in s.edges}
                       for r, (_, s) in sweep.items())
            row["identical"] = same
            row["edges"] = [derived[r].n_edges for r in SWEEP]
        rows.append(row)
        print(f"repeat {rep + 1}: " + ", ".join(f"{k} {v:.2f} s" if isinstance(v, float) else f"{k} {v}"
                                              for k, v in row.items()))
    med = {k: statistics.median(r[k] for r in rows) for k in rows[0] if isinstance(rows[0][k], float)}
    ratio = {k: statistics.median(r[k] / r["a"] for r in rows) for k in med if k != "a"}
    crit = table.critical()
    print(f"candidates {table.n_instances} (pair, L), pairs {len(crit.value)}, exact pairs {int(crit.exact.sum())}, "
          f"HiGHS solves of the exact curve {table.stats['refine_highs_solves']}, PDHG iterations median "
          f"{table.stats['iterations_median']:.0f}; one abstraction: {ts.n_edges} edges, {ts.stats['n_lps']} LPs")
    names = {"b": "curve (certified brackets)", "c": "exact curve", "d": "7-point sweep",
             "e": "7 systems from the table"}
    print(f"(a) one abstraction at r = {a.radius}: median {med['a']:.2f} s")
    for k, v in ratio.items():
        print(f"({k}) {names[k]}: median {med[k]:.2f} s, {v:.2f}x (a)")
    if "identical" in rows[0]:
        print(f"derived systems identical to the sweep's at r = {list(SWEEP)}: {all(r['identical'] for r in rows)} "
              f"(edges {rows[-1]['edges']})")


if __name__ == "__main__":
    main()
