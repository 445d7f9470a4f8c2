"""Time the LTLf planning pipeline (parse + DFA, tube labelling, product, Dijkstra) on abstractions.

Examples
--------
python experiments/benchmark_spec.py                                  # paper (334 edges) and large (2,782)
python experiments/benchmark_spec.py --maps paper --repeats 10
python experiments/benchmark_spec.py --abstraction-dir paper=outputs/.../ --abstraction-dir large=/tmp/large

Each abstraction is built with HiGHS (r = 0.2, L_max = 10) unless a directory is given. Times are
medians over ``--repeats`` runs on this machine; the edge labelling (exact polytope tests for every
tube set against every labelled cell) is the part that grows with the number of edges.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MAPS = {"paper": ("conf/workspace/maps/paper.txt", "F(l3 & F(l5 & F(l6))) & G(!l4)"),
        "large": ("conf/workspace/maps/large.txt", "F(l2 & F(l3)) & G(!l4)")}


def abstraction(name, directory):
    from tubejax.abstraction import build_abstraction
    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set
    from tubejax.transitions.transition_system import TransitionSystem
    from tubejax.model.workspace.gridmap import load_grid_map

    if directory:
        return TransitionSystem.load(directory)
    d = load_grid_map(ROOT / MAPS[name][0])
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    return build_abstraction(d, s, L_max=10, progress=False)


def timed(fn, repeats):
    out, ts = None, []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return out, statistics.median(ts)


def main(argv=None) -> int:
    from tubejax.analyses.spec import (build_product, dfa_from_formula, edge_letters, map_alphabet, parse_formula,
                                       plan_dfa, plan_formula)

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--maps", default="paper,large")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--abstraction-dir", action="append", default=[], metavar="NAME=DIR")
    args = ap.parse_args(argv)
    dirs = dict(a.split("=", 1) for a in args.abstraction_dir)
    print("| map | cells | edges | tube sets | DFA states | parse + DFA | labelling | product | Dijkstra | "
          "plan_formula (all) | plan steps |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.maps.split(","):
        if name not in MAPS:
            print(f"error: unknown map {name!r} (choose from {sorted(MAPS)})", file=sys.stderr)
            return 2
        ts = abstraction(name, dirs.get(name))
        formula = MAPS[name][1]
        start = ts.decomposition.cells_with_label("1")[0]
        labels = ts.decomposition.labels
        def dfa_of():
            p = parse_formula(formula, labels)
            return dfa_from_formula(p, map_alphabet(ts.decomposition, p.labels))

        dfa, t_dfa = timed(dfa_of, args.repeats)
        lt, t_lab = timed(lambda: edge_letters(ts, dfa.labels), args.repeats)
        prod, t_prod = timed(lambda: build_product(ts, dfa, lt), args.repeats)
        sp, t_plan = timed(lambda: plan_dfa(ts, start, dfa, letters=lt, product=prod), args.repeats)
        _, t_all = timed(lambda: plan_formula(ts, start, formula), args.repeats)
        print(f"| {name} | {ts.n_cells} | {ts.n_edges} | {int(lt.L.sum())} | {dfa.n_states} | "
              f"{1e3 * t_dfa:.1f} ms | {1e3 * t_lab:.1f} ms | {1e3 * t_prod:.1f} ms | {1e3 * t_plan:.1f} ms | "
              f"{1e3 * t_all:.1f} ms | {sp.cost} |")
    print("formulas: " + "; ".join(f"{k}: {v[1]}" for k, v in MAPS.items() if k in args.maps.split(",")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
