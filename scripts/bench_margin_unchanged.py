"""Check that the margin form is unchanged by the radius form: the hash of its lowered
StableHLO (debug info stripped, tube and open-loop runners) and the time of one margin-form
abstraction (paper map, r = 0.2, L_max = 10, compile excluded, median of repeats).

Run it against two checkouts and compare, e.g.

    PYTHONPATH=/path/to/main  python scripts/bench_margin_unchanged.py
    PYTHONPATH=$PWD           python scripts/bench_margin_unchanged.py
"""

from __future__ import annotations

import argparse
import hashlib
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

import tubejax  # noqa: E402
from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.lp.engines.pdhg_adapters import flat_ops, pdhg_setup  # noqa: E402
from tubejax.lp.evidence.records.openloop_record import OPENLOOP_PDHG  # noqa: E402
from tubejax.lp.evidence.records.tube_record import TUBE_PDHG  # noqa: E402
from tubejax.model.zshape.kinds import make_z  # noqa: E402
from tubejax.lp.batch.batch_solver import PdhgBatchSolver  # noqa: E402
from tubejax.lp.engines.pdhg import make_pdhg_runner  # noqa: E402
from tubejax.lp.engines.pool import Layout  # noqa: E402
from tubejax.model.problem import pair_problem  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace import load_grid_map  # noqa: E402


def hlo_hashes(dec, sysm):
    Z = [make_z("box", c) for c in dec.cells]
    probs = [pair_problem(dec, sysm, Z[i], i, j, 5) for i in range(4) for j in range(6) if i != j]
    out = {}
    for name, fm in (("tube", TUBE_PDHG), ("openloop", OPENLOOP_PDHG)):
        opts = PdhgBatchSolver(form=fm).options
        f_pad = tuple(np.max([fm.facet_counts(p) for p in probs], axis=0))
        shape, _, prob, state = pdhg_setup(fm, probs, 8, f_pad, opts, True)
        mv, rmv, cert = flat_ops(fm.operator, shape, jnp)
        layouts = (Layout.of(prob), Layout.of(state))
        txt = make_pdhg_runner(mv, rmv, cert, opts).lower(
            *(lay.abstract(32) for lay in layouts), 0, layouts).as_text(debug_info=False)
        out[name] = hashlib.sha256(txt.encode()).hexdigest()[:16]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--map", default="conf/workspace/maps/paper.txt")
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args()
    dec = load_grid_map(a.map)
    sysm = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    print("tubejax from", tubejax.__file__)
    print("StableHLO sha256 of the margin runners:", hlo_hashes(dec, sysm))
    solver = PdhgBatchSolver()
    build_abstraction(dec, sysm, L_max=10, solve_batch=solver, progress=False)     # compiles
    times, dev, its = [], [], []
    for _ in range(a.repeats):
        solver.reset_stats()
        t0 = time.perf_counter()
        ts = build_abstraction(dec, sysm, L_max=10, solve_batch=solver, progress=False)
        times.append(time.perf_counter() - t0)
        dev.append(solver.stats["device_seconds"])
        its.append(solver.stats["slot_iterations"])
    print(f"edges {ts.stats['n_edges']}, LPs {ts.stats['n_lps']}, slot iterations {its[-1]}")
    print(f"abstraction: median {statistics.median(times):.3f} s ({', '.join(f'{t:.2f}' for t in times)}); "
          f"device median {statistics.median(dev):.3f} s, "
          f"{1e6 * statistics.median(dev) / its[-1]:.2f} us per LP-iteration")


if __name__ == "__main__":
    main()
