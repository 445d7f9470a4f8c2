"""Issue 12's agreement target: at every radius of a 7-point sweep from 0 to 0.3, the transition
system derived from ONE rho* solve (:mod:`tubejax.analyses.radius_analysis`: the batched engine, HiGHS at
ties, every edge confirmed and proved at its radius) is identical -- edges and L -- to a direct
Algorithm 2 run at that radius (:func:`tubejax.abstraction.build_abstraction` with the batched
engine, what ``experiments/abstract.py`` runs), for the tube and the open-loop methods.

Usage::

    python scripts/check_radius_agreement.py                         # corridor, maze, paper
    python scripts/check_radius_agreement.py --maps conf/workspace/maps/corridor.txt --forms tube
    python scripts/check_radius_agreement.py --input-set one_norm     # the 1-norm U: hard input rows

Exits 1 if any system differs.
"""

from __future__ import annotations

import argparse
import sys
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from tubejax.abstraction import build_abstraction, cross_sections  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.lp.batch.batch_solver import pdhg_solver  # noqa: E402
from tubejax.lp.engines.workers import shared_process_workers  # noqa: E402
from tubejax.analyses.radius_analysis import RadiusTableOptions, solve_radius_table, transition_system_at  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set  # noqa: E402
from tubejax.model.workspace import load_grid_map  # noqa: E402

MAPS = ("conf/workspace/maps/corridor.txt", "conf/workspace/maps/maze.txt", "conf/workspace/maps/paper.txt")
RADII = (0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--maps", default=",".join(MAPS))
    ap.add_argument("--forms", default="tube,openloop")
    ap.add_argument("--L-max", type=int, default=10)
    ap.add_argument("--input-set", choices=("box", "one_norm"), default="box",
                    help="U: the box |u_i| <= 1 (bounds) or the 1-norm ball |u_1| + |u_2| <= 1 (hard rows)")
    a = ap.parse_args()
    U = box_input_set(1.0, 2) if a.input_set == "box" else one_norm_input_set(1.0, 2)
    workers = shared_process_workers()
    solvers = {form: (pdhg_solver(form), pdhg_solver(form, radius=True)) for form in a.forms.split(",")}
    ok = True
    for path in a.maps.split(","):
        dec = load_grid_map(path)
        sysm = {r: LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=U, W=Ball(2, r)) for r in RADII}
        Z = cross_sections(dec, "box", 1.0)
        for form in a.forms.split(","):
            margin, radius = solvers[form]
            t0 = time.perf_counter()
            table = solve_radius_table(dec, sysm[0.2], Z=Z, options=RadiusTableOptions(form=form, L_max=a.L_max),
                                       solver=radius, workers=workers)
            table.refine(workers=workers)
            t_table = time.perf_counter() - t0
            for r in RADII:
                t1 = time.perf_counter()
                ts = transition_system_at(table, r, workers=workers)
                t_derived = time.perf_counter() - t1
                direct = build_abstraction(dec, sysm[r], L_max=a.L_max, solve_batch=margin, progress=False,
                                           method=form)
                want = {(e.src, e.dst): e.L for e in direct.edges}
                got = {(e.src, e.dst): e.L for e in ts.edges}
                same = want == got
                ok &= same
                print(f"{path.split('/')[-1]:13s} {form:8s} r = {r:<5g} edges {len(want):4d} derived {len(got):4d} "
                      f"identical {same}  (HiGHS solves {ts.stats['n_lps']}, ties {ts.stats['n_ties']}, "
                      f"curve n_edges(r) {int(table.n_edges()(r))}, system {t_derived:.1f} s)", flush=True)
            print(f"{path.split('/')[-1]:13s} {form:8s} table: {table.n_instances} candidates in {t_table:.1f} s "
                  f"(incl. compile {table.stats['compile_seconds']:.1f} s)", flush=True)
    print("ALL IDENTICAL" if ok else "DIFFERENCES FOUND")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
