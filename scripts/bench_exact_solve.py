"""Exact linear solves: FLINT's rational matrices against sparse elimination over Fractions.

    python scripts/bench_exact_solve.py              # 5 repeats, medians
    python scripts/bench_exact_solve.py --repeats 9

The workload: exact decisions without HiGHS's basis (the exact simplex from a cold start, then
the exact check), on the zero-margin and the infeasible moves of tests/lp/test_exact_decision.py
(an open 7 x 2 grid, the paper's system, box ``Z``). Prints the medians of (1) every basic system
those decisions solve, by :func:`tubejax.lp.evidence.basis.solve_exact` and by the sparse Fraction
elimination it replaced (kept below as the reference, with Markowitz pivots), after checking that
both give the same solution; (2) the decisions end to end with either solver. CPU times
(``time.process_time``): the machine may be shared.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

import tubejax.lp.evidence.basis as basis_module
import tubejax.lp.evidence.simplex as simplex_module
from tubejax.abstraction import cross_sections
from tubejax.lp.evidence.basis import BasisError, solve_exact
from tubejax.lp.evidence.decide import decide_exactly
from tubejax.lp.declarations.tube_lp import build_tube_lp
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.model.geometry import Ball
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import parse_grid_map

#: (source, target, L): zero-margin edges (L = 10 for a move of three columns) and refutations.
CASES = ((1, 4, 10), (1, 4, 9), (0, 3, 10), (2, 5, 9), (1, 3, 7), (1, 3, 6))


def fraction_solve(rows: list, rhs: list, unknowns: list) -> dict:
    """The reference: sparse Gaussian elimination over Fractions, Markowitz pivots."""
    if len(rows) != len(unknowns):
        raise BasisError("not square")
    R, b = [dict(r) for r in rows], list(rhs)
    where: dict = {u: set() for u in unknowns}
    for i, r in enumerate(R):
        for u in r:
            where[u].add(i)
    alive, order = set(unknowns), []
    while alive:
        u = min(alive, key=lambda c: len(where[c]))
        if not where[u]:
            raise BasisError("singular")
        i = min(where[u], key=lambda k: len(R[k]))
        piv_row, piv = R[i], R[i][u]
        for c in piv_row:
            where[c].discard(i)
        for k in list(where[u]):
            r = R[k]
            f = r[u] / piv
            for c, a in piv_row.items():
                v = r.get(c, 0) - f * a
                if v:
                    if c not in r:
                        where[c].add(k)
                    r[c] = v
                elif c in r:
                    del r[c]
                    where[c].discard(k)
            b[k] -= f * b[i]
        alive.discard(u)
        order.append((u, i))
    x: dict = {}
    for u, i in reversed(order):
        r = R[i]
        x[u] = (b[i] - sum(a * x[c] for c, a in r.items() if c != u)) / r[u]
    return x


def use(solver) -> None:
    basis_module.solve_exact = simplex_module.solve_exact = solver


def decide_all(instances) -> list:
    return [decide_exactly(prob, lp, res._replace(status="Unknown", col_status=None, row_status=None)).status
            for prob, lp, res in instances]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    d = parse_grid_map("\n".join(["." * 7] * 2))
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    Z = cross_sections(d, "box", 1.0)
    instances = []
    for i, j, L in CASES:
        prob = pair_problem(d, sysm, Z[i], i, j, L)
        lp = build_tube_lp(prob)
        instances.append((prob, lp, solve_margin_lp(lp)))
    systems = []

    def record(rows, rhs, unknowns):
        systems.append(([dict(r) for r in rows], list(rhs), list(unknowns)))
        return solve_exact(rows, rhs, unknowns)

    use(record)
    statuses = decide_all(instances)
    use(solve_exact)
    for s in systems:
        if solve_exact(*s) != fraction_solve(*s):
            raise SystemExit("the two solvers differ")
    sizes = [len(s[2]) for s in systems]
    print(f"decisions: {statuses}; {len(systems)} basic systems, {min(sizes)} to {max(sizes)} unknowns, "
          f"the same solution by both solvers")

    def timed(fn):
        t = time.process_time()
        fn()
        return time.process_time() - t

    for name, solver in (("Fraction elimination", fraction_solve), ("python-flint fmpq_mat", solve_exact)):
        solves = statistics.median(timed(lambda: [solver(*s) for s in systems]) for _ in range(args.repeats))
        use(solver)
        if decide_all(instances) != statuses:
            raise SystemExit(f"{name}: other decisions")
        whole = statistics.median(timed(lambda: decide_all(instances)) for _ in range(args.repeats))
        use(solve_exact)
        print(f"{name:22s} the basic systems {solves:6.3f} s   the decisions end to end {whole:6.3f} s "
              f"(medians of {args.repeats})")


if __name__ == "__main__":
    main()
