"""Benchmark: sequential HiGHS vs the batched, verified PDHG path vs MPAX, on the same candidate LPs.

Prints, for each map, in one run (ratios measured side by side: (a) and (b) alternate,
medians over repeats):
(a) sequential HiGHS, (b) the batched PDHG path with verification, (c) MPAX (``pip install mpax``)
solving the same candidate LPs (vmapped per shape; ``--mpax-limit`` caps how many, and the total
is then extrapolated from the per-LP time, which is said), a/b and c/b, the compile time,
iterations per instance (median, p99), and the agreement counts; and (d) ``K^T`` of the tube
operator two ways on the map's pairs at ``L_max``: the fused ``tube_rmatvec`` against
``jax.linear_transpose`` of ``tube_matvec`` (the derived transpose), jitted, alternating, medians;
and (e) the same for the open-loop operator (``openloop_rmatvec`` against the transpose of
``openloop_matvec``) on the same pairs.

Usage
-----
python experiments/benchmark.py                    # paper map and the 16x16 map, r = 0.2, L_max = 10
python experiments/benchmark.py --maps paper --repeats 5 --no-mpax
python experiments/benchmark.py --maps rooms:1150 --repeats 1 --no-mpax   # the 40x40-style map

(a) settles the translates of infeasible pairs by class as (b) does (the class rule is not a switch:
sequential HiGHS on every candidate LP is measured by an older release's ``--highs-every``, e.g.
17863db, in its own tree).

Against a recorded release, ``experiments/compare_releases.py --base REF`` runs this script's
``load_map``, ``run_side_by_side`` and ``bench_transpose`` on both trees in turn (keep their
signatures, or that script's worker, in step).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.lp.declarations.tube_lp import build_tube_lp  # noqa: E402
from tubejax.lp.declarations.margin_operator import pack  # noqa: E402
from tubejax.lp.declarations.tube_operator import (tube_dims, tube_matvec, tube_rmatvec,  # noqa: E402
                                                   unpack_x, unpack_y)
from tubejax.lp.declarations.tube_operator_data import build_tube_data  # noqa: E402
from tubejax.lp.declarations.openloop_operator import (openloop_dims,  # noqa: E402
                                                       openloop_matvec, openloop_rmatvec)
from tubejax.lp.declarations.openloop_operator_data import build_openloop_data  # noqa: E402
from tubejax.lp.declarations.openloop_operator import unpack_x as ol_unpack_x, unpack_y as ol_unpack_y  # noqa: E402
from tubejax.model.zshape.kinds import make_z  # noqa: E402
from tubejax.model.problem import pair_problem  # noqa: E402
from tubejax.lp.evidence.verdict import highs_solve_batch  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace import load_grid_map  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def edges_of(ts):
    return {(e.src, e.dst): e.L for e in ts.edges}


def run_highs(decomp, system, L_max):
    cands = []

    def recording(problems, progress=None):
        cands.extend(problems)
        return highs_solve_batch(problems, progress)

    t0 = time.perf_counter()
    ts = build_abstraction(decomp, system, L_max=L_max, solve_batch=recording, progress=False)
    return ts, time.perf_counter() - t0, cands


def run_side_by_side(decomp, system, L_max, repeats):
    """(a) and (b) in turn, ``repeats`` times each, after one warm-up
    (compiling) run of (b).

    Alternating keeps slow phases of a shared machine from favouring either side; the
    ratio is reported as the median of the per-repeat ratios.
    """
    from tubejax.lp.batch.batch_solver import PdhgBatchSolver

    solver = PdhgBatchSolver()
    t0 = time.perf_counter()
    ts_p = build_abstraction(decomp, system, L_max=L_max, solve_batch=solver, progress=False)
    first = time.perf_counter() - t0
    compile_s = solver.stats["compile_seconds"]
    n_compiles = solver.stats["n_compiles"]
    t_a, t_b, stats, cands = [], [], None, None
    for _ in range(repeats):                       # compiled executables are kept between runs
        ts_h, dt, cands = run_highs(decomp, system, L_max)
        t_a.append(dt)
        solver.reset_stats()
        t0 = time.perf_counter()
        ts_p = build_abstraction(decomp, system, L_max=L_max, solve_batch=solver, progress=False)
        t_b.append(time.perf_counter() - t0)
        stats = dict(solver.stats, n_compiles=n_compiles)
    return ts_h, ts_p, cands, t_a, t_b, first, compile_s, stats


def run_mpax(cands, limit):
    """Solve the candidate margin LPs with MPAX's r2HPDHG, vmapped over same-shaped groups."""
    try:
        import mpax
    except ImportError:
        return None
    step = max(1, len(cands) // max(limit, 1))
    lps = [build_tube_lp(p) for p in cands[::step][:limit]]          # evenly spread over the rounds
    groups = {}
    for k, lp in enumerate(lps):
        groups.setdefault((lp.G.shape, lp.G_hard.shape), []).append(k)
    solver = mpax.r2HPDHG(eps_abs=1e-6, eps_rel=1e-6, iteration_limit=20000, verbose=False)

    import jax.numpy as jnp

    def solve_one(G, g, lb, ub):
        nr, nx = G.shape
        A_ineq = -jnp.hstack([G, jnp.ones((nr, 1))])          # MPAX: G x >= h
        c = jnp.zeros(nx + 1).at[-1].set(-1.0)
        lp = mpax.create_lp(c, jnp.zeros((0, nx + 1)), jnp.zeros(0), A_ineq, -g,
                            jnp.append(lb, -1e3), jnp.append(ub, 1.0), use_sparse_matrix=False)
        return solver.optimize(lp)

    batched = jax.jit(jax.vmap(solve_one))
    margins = np.full(len(lps), np.nan)
    iters = np.zeros(len(lps))
    compile_s = solve_s = 0.0
    for keys in groups.values():
        G = np.stack([lps[k].G for k in keys])
        g = np.stack([lps[k].g for k in keys])
        lb = np.stack([lps[k].lb for k in keys])
        ub = np.stack([lps[k].ub for k in keys])
        t0 = time.perf_counter()
        comp = batched.lower(G, g, lb, ub).compile()
        compile_s += time.perf_counter() - t0
        t0 = time.perf_counter()
        out = comp(G, g, lb, ub)
        jax.block_until_ready(out)
        solve_s += time.perf_counter() - t0
        margins[keys] = np.asarray(out.primal_solution)[:, -1]
        iters[keys] = np.asarray(out.iteration_count)
    return {"n": len(lps), "solve_seconds": solve_s, "compile_seconds": compile_s,
            "per_lp": solve_s / max(len(lps), 1), "margins": margins, "iterations": iters}


def load_map(name):
    """A map of conf/workspace/maps by name, or ``rooms:N`` (a seeded rooms-and-corridors map of
    about N free cells, :func:`tubejax.model.workspace.generate.rooms_and_corridors_map`, seed 0)."""
    if name.startswith("rooms:"):
        from tubejax.model.workspace import parse_grid_map
        from tubejax.model.workspace.generate import rooms_and_corridors_map
        return parse_grid_map(rooms_and_corridors_map(int(name.split(":")[1]), seed=0), name=name)
    return load_grid_map(ROOT / "conf" / "workspace" / "maps" / f"{name}.txt")


def bench_map(name, radius, L_max, repeats, mpax_limit, use_mpax):
    decomp = load_map(name)
    system = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, radius))
    ts_h, ts_p, cands, t_a, t_b, first, compile_s, st = run_side_by_side(decomp, system, L_max, repeats)
    a, b = statistics.median(t_a), statistics.median(t_b)
    ratio = statistics.median([x / y for x, y in zip(t_a, t_b)])
    same = edges_of(ts_h) == edges_of(ts_p)
    row = {"map": name, "cells": decomp.n_cells, "candidate_lps": len(cands), "edges": ts_h.n_edges,
           "highs_seconds": a, "highs_seconds_all": t_a, "pdhg_seconds_median": b, "pdhg_seconds_all": t_b,
           "pdhg_first_run_seconds": first, "compile_seconds": compile_s, "a_over_b": ratio,
           "iterations_median": st.get("iterations_median"), "iterations_p99": st.get("iterations_p99"),
           "certified_feasible": st.get("certified_feasible"),
           "certified_infeasible": st.get("certified_infeasible"), "sent_to_highs": st.get("sent_to_highs"),
           "highs_disagreements": st.get("highs_disagreements"), "edges_agree": same,
           "device_seconds": st.get("device_seconds"), "n_compiles": st.get("n_compiles")}
    fmt = lambda v: ", ".join(f"{x:.2f}" for x in v)                     # noqa: E731
    print(f"\n== {name}: {decomp.n_cells} cells, {len(cands)} candidate LPs after pruning, "
          f"{ts_h.n_edges} edges (r = {radius}, L_max = {L_max})")
    print(f"(a) sequential HiGHS          : {a:8.2f} s   median of {repeats} [{fmt(t_a)}] "
          f"({1e3 * a / max(len(cands), 1):.2f} ms/LP)")
    print(f"(b) batched PDHG + verification: {b:8.2f} s   median of {repeats} [{fmt(t_b)}]; "
          f"first run {first:.2f} s incl. compile")
    print(f"    of which PDHG (no HiGHS)  : {st.get('pdhg_seconds', float('nan')):8.2f} s "
          f"(jitted calls {st.get('device_seconds', float('nan')):.2f} s); HiGHS confirmations "
          f"{st.get('highs_confirmations')} + fallbacks {st.get('sent_to_highs')} "
          f"({st.get('highs_cpu_seconds', float('nan')):.2f} s inside HiGHS, "
          f"{st.get('highs_wait_seconds', float('nan')):.2f} s waited for in rounds, "
          f"{ts_p.stats.get('confirm_wait_seconds', float('nan')):.2f} s after the last)")
    print(f"    compile                   : {compile_s:8.2f} s   ({st.get('n_compiles')} executables)")
    print(f"    a / b                     : {ratio:8.2f}   (median of the {repeats} side-by-side ratios)")
    print(f"    iterations per instance   : median {st.get('iterations_median')}, p99 {st.get('iterations_p99')}")
    print(f"    certified feasible {st.get('certified_feasible')}, certified infeasible "
          f"{st.get('certified_infeasible')}, sent to HiGHS {st.get('sent_to_highs')}, "
          f"HiGHS disagreements {st.get('highs_disagreements')}; edges and L equal to HiGHS: {same}")
    if use_mpax:
        m = run_mpax(cands, mpax_limit)
        if m is None:
            print("(c) MPAX                      : not installed (pip install 'tubejax[mpax]')")
        else:
            c = m["per_lp"] * len(cands)
            note = "" if m["n"] == len(cands) else f" (extrapolated from {m['n']} LPs)"
            finite = np.isfinite(m["margins"])
            print(f"(c) MPAX r2HPDHG (vmapped)    : {c:8.2f} s{note}; compile {m['compile_seconds']:.1f} s; "
                  f"iterations median {np.median(m['iterations']):.0f}, p99 {np.percentile(m['iterations'], 99):.0f}; "
                  f"NaN margins {int((~finite).sum())}")
            print(f"    c / b                     : {c / b:8.2f}   (MPAX: no certificates, no HiGHS confirmation)")
            row.update({"mpax_seconds": c, "mpax_lps": m["n"], "mpax_compile_seconds": m["compile_seconds"],
                        "c_over_b": c / b})
    return row


def bench_transpose(decomp, system, L, repeats, applications=50):
    """(d) and (e): seconds for ``applications`` products ``K^T y`` over the ordered pairs of the map's
    first 40 cells at horizon ``L`` (one group, shared ``Z``), for the tube operator (d) and the
    open-loop operator (e): fused vs ``jax.linear_transpose``; medians and the median of the
    side-by-side ratios. The two results are compared too."""
    import jax.numpy as jnp

    Z = [make_z("box", c) for c in decomp.cells]
    k = min(decomp.n_cells, 40)                        # the first 40 cells' ordered pairs
    probs = [pair_problem(decomp, system, Z[i], i, j, L) for i in range(k) for j in range(k) if i != j]
    shape, data = build_tube_data(probs, share=True)
    row = _time_transpose("(d) K^T", "transpose", shape, jax.tree_util.tree_map(jnp.asarray, data.lean()),
                          tube_dims, tube_matvec, tube_rmatvec, (unpack_x, unpack_y), len(probs), L, repeats,
                          applications)
    shape, data = build_openloop_data(probs)
    row.update(_time_transpose("(e) open-loop K^T", "openloop_transpose", shape,
                               jax.tree_util.tree_map(jnp.asarray, data.lean()), openloop_dims, openloop_matvec,
                               openloop_rmatvec, (ol_unpack_x, ol_unpack_y), len(probs), L, repeats, applications))
    return row


def _time_transpose(label, key, shape, d, dims, matvec, rmatvec, unpacking, B, L, repeats, applications):
    """One operator's fused ``rmatvec`` against ``jax.linear_transpose`` of its ``matvec`` (jitted,
    alternating, medians)."""
    import jax.numpy as jnp

    unpack_x_, unpack_y_ = unpacking
    nx, nr = dims(shape)
    y = jnp.asarray(np.random.default_rng(0).standard_normal((nr, B)))
    z = jnp.zeros((nx + 1, B))

    def fused(y):
        return pack(rmatvec(shape, d, unpack_y_(shape, y, jnp), jnp), jnp)

    def derived(y):
        mv = lambda v: pack(matvec(shape, d, unpack_x_(shape, v, jnp), jnp), jnp)   # noqa: E731
        return jax.linear_transpose(mv, z)(y)[0]

    def loop(fn):
        return jax.jit(lambda y: jax.lax.fori_loop(0, applications, lambda i, acc: acc + fn(y + i * 1e-9),
                                                   jnp.zeros((nx + 1, B))))
    f, g = loop(fused), loop(derived)
    diff = float(jnp.max(jnp.abs(f(y) - g(y))))
    t_f, t_d = [], []
    for _ in range(max(repeats, 3)):
        t0 = time.perf_counter()
        f(y).block_until_ready()
        t_f.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        g(y).block_until_ready()
        t_d.append(time.perf_counter() - t0)
    ratio = statistics.median([b / a for a, b in zip(t_f, t_d)])
    print(f"{label}, {B} instances at L = {L}, {applications} products: fused {statistics.median(t_f):.3f} s, "
          f"jax.linear_transpose {statistics.median(t_d):.3f} s, derived / fused {ratio:.2f} "
          f"(max difference {diff:.1e})")
    return {f"{key}_instances": B, f"{key}_fused_seconds": statistics.median(t_f),
            f"{key}_derived_seconds": statistics.median(t_d), f"{key}_derived_over_fused": ratio}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="HiGHS vs batched PDHG vs MPAX on the tube LPs")
    ap.add_argument("--maps", default="paper,large",
                    help="comma-separated names in conf/workspace/maps, or rooms:N (a generated ~N-cell map)")
    ap.add_argument("--radius", type=float, default=0.2)
    ap.add_argument("--L-max", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--mpax-limit", type=int, default=1024)
    ap.add_argument("--no-mpax", action="store_true")
    ap.add_argument("--out", type=Path, default=None, help="write the figures as JSON here")
    args = ap.parse_args(argv)
    print(f"devices: {jax.devices()}")
    rows = []
    for m in args.maps.split(","):
        rows.append(bench_map(m, args.radius, args.L_max, args.repeats, args.mpax_limit, not args.no_mpax))
        system = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, args.radius))
        rows[-1].update(bench_transpose(load_map(m), system, args.L_max, args.repeats))
    if args.out:
        args.out.write_text(json.dumps(rows, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
