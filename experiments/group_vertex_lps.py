"""Benchmark: HiGHS on the drone's joint and projected LPs, full against one input column per group vertex
(:mod:`tubejax.abstraction.group_vertex_lp`; a script, not a test).

Lifts the map as ``experiments/drone_scale.py`` does, joins, draws ``--sample`` joint pairs (seed 0) and runs
their joint phase (projection screen, then the joint LPs) twice: with HiGHS on the full LPs (as before) and on
the group-vertex LPs, and compares the edges, ``L``, margins and proof levels. Then, per LP, in
CPU seconds (``time.process_time``, the fastest of ``--repeat`` rounds): HiGHS on the full LP as the verdicts
solve it, HiGHS on the group-vertex LP, and the reduction's own cost (making the LP and mapping the answer
back). Three sets: the joint LPs the phase solved (edges), the first ``--extra`` joint LPs of the sample in
order of ``L`` (most of them refuted by the screen, so solved here only), and the first ``--projected``
projected LPs.
Prints medians, the largest margin difference, and how many answers
:func:`~tubejax.abstraction.group_vertex_lp.solve_by_group_vertices` took from the reduced LP.

Usage
-----
python experiments/group_vertex_lps.py conf/workspace/maps/building3d_small.txt 5,4,5 --sample 300
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from tubejax.abstraction import group_vertex_lp as gv  # noqa: E402
from tubejax.abstraction.joint_duals import DualReuseSolver  # noqa: E402
from tubejax.abstraction.joint_projections import ProjectionScreen, _ScreenSolver  # noqa: E402
from tubejax.abstraction.product_joint_lps import joint_pairs  # noqa: E402
from tubejax.abstraction.product_factors import solve_factor  # noqa: E402
from tubejax.abstraction.product_join import join_factors  # noqa: E402
from tubejax.lp.declarations.tube_lp import build_tube_lp  # noqa: E402
from tubejax.lp.engines.highs import solve_margin_lp  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.model.problem import Pairs, pair_problems  # noqa: E402
from tubejax.model.product_structure import product_structure  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.system_kinds import double_integrator_lookahead  # noqa: E402
from tubejax.model.workspace.lookahead import lift_lookahead  # noqa: E402
from tubejax.model.workspace.voxelmap import parse_map  # noqa: E402
from tubejax.model.zshape.kinds import cross_sections  # noqa: E402


def _recording(cls):
    """``cls`` (a :class:`DualReuseSolver`) that keeps every problem it is asked."""
    class Recording(cls):
        def __init__(self, *a):
            super().__init__(*a)
            self.problems = []

        def verdict(self, prob):
            self.problems.append(prob)
            return super().verdict(prob)
    return Recording


def _full(prob, lp):
    """The last :func:`~tubejax.abstraction.group_vertex_lp.full_solve` answer (stands in for it)."""
    _full.last = _FULL_SOLVE(prob, lp)
    return _full.last


_FULL_SOLVE = gv.full_solve
gv.full_solve = _full


def _cpu(fn, repeat: int) -> tuple:
    """The fastest CPU seconds of ``fn()`` over ``repeat`` calls, and its last value."""
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.process_time()
        out = fn()
        best = min(best, time.process_time() - t0)
    return best, out


def time_lps(problems, repeat: int) -> dict:
    """Per LP: CPU seconds of HiGHS on the full LP and on the group-vertex LP, the reduction's cost, the
    margins, and whether :func:`~tubejax.abstraction.group_vertex_lp.solve_by_group_vertices` answered from
    the reduced LP."""
    rows = []
    for prob in problems:
        lp = build_tube_lp(prob)
        t_full, full = _cpu(lambda: solve_margin_lp(lp, basis_min_margin=-1e-6), repeat)
        t_make, red = _cpu(lambda: gv.group_vertex_lp(prob, lp), repeat)
        t_red, res = _cpu(lambda: solve_margin_lp(red.lp), repeat)
        t_map, _ = _cpu(lambda: gv.expanded_result(red, res, lp), repeat)
        _full.last = None
        used = gv.solve_by_group_vertices(prob, lp) is not _full.last
        rows.append((t_full, t_red, t_make + t_map, full.margin, res.margin, used, lp.G.shape, red.lp.G.shape))
    return rows


def report(name: str, rows) -> None:
    if not rows:
        print(f"{name}: none")
        return
    a = np.array([r[:5] for r in rows], float)
    print(f"{name}: {len(rows)} LPs, full {rows[0][6]} -> reduced {rows[0][7]} (the first); median CPU ms: HiGHS full "
          f"{1e3 * np.median(a[:, 0]):.1f}, HiGHS reduced {1e3 * np.median(a[:, 1]):.2f}, reduction "
          f"{1e3 * np.median(a[:, 2]):.2f}; total HiGHS s {a[:, 0].sum():.2f} -> {a[:, 1].sum():.2f}; "
          f"max |margin difference| {np.max(np.abs(a[:, 3] - a[:, 4])):.2e}; answered from the reduced LP: "
          f"{sum(r[5] for r in rows)}", flush=True)


def compare(full, red) -> None:
    """The two joint phases' edges, ``L``, margins and proof levels, refuted pair horizons and LPs."""
    (j1, s1, v1, L1, m1, t1), (j2, s2, v2, L2, m2, t2) = full, red
    levels = [(v1[k].proof.level, v2[k].proof.level) for k in L1 if k in L2]
    print(f"joint phase, full LPs: {len(L1)} edges, {s1.n_refuted} pair horizons refuted by {s1.n_lps} projected LPs, "
          f"{len(j1.problems)} joint LPs, {t1:.1f} CPU s; group-vertex LPs: {len(L2)} edges, {s2.n_refuted} refuted by "
          f"{s2.n_lps}, {len(j2.problems)} joint LPs, {t2:.1f} CPU s (the second run, warm caches)", flush=True)
    print(f"same edges and L: {L1 == L2}; max |margin difference| "
          f"{max((abs(m1[k] - m2[k]) for k in L1 if k in L2), default=0.0):.2e}, bit-identical "
          f"{sum(m1[k] == m2[k] for k in L1 if k in L2)}; proof levels (full, group-vertex): "
          f"{ {lv: levels.count(lv) for lv in set(levels)} }", flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("map_file")
    ap.add_argument("divisions")
    ap.add_argument("--sample", type=int, default=300)
    ap.add_argument("--extra", type=int, default=40)
    ap.add_argument("--projected", type=int, default=200)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args(argv)
    decomp = lift_lookahead(parse_map(Path(args.map_file).read_text(), args.map_file),
                            [int(x) for x in args.divisions.split(",")])
    A, B = double_integrator_lookahead(3, 0.5, 2.0)
    system = LinearSystem(A=A.astype(float), B=B.astype(float), U=box_input_set(1.0, 3), W=Ball(6, 0.01))
    Zs = cross_sections(decomp, "cell", 1.0)
    structure = product_structure(decomp, system, Zs)
    tables = [solve_factor(f, g, 8) for g, f in enumerate(structure.factors)]
    joined = join_factors(decomp, structure, tables, 256.0)
    k = np.sort(np.random.default_rng(0).choice(len(joined.joint_src), args.sample, replace=False))
    joined = dataclasses.replace(joined, joint_src=joined.joint_src[k], joint_dst=joined.joint_dst[k],
                                 joint_box_mask=joined.joint_box_mask[k])
    runs = {}
    for name, solve_lp in (("full", None), ("group-vertex", gv.solve_by_group_vertices)):
        joint = _recording(DualReuseSolver)(solve_lp)
        screen = ProjectionScreen(structure, system, solve_batch=_recording(_ScreenSolver)(solve_lp))
        t0 = time.process_time()
        verdicts, L_of, margin_of, _ = joint_pairs(decomp, system, Zs, joined, 8, 0.0, joint, screen)
        runs[name] = (joint, screen, verdicts, L_of, margin_of, time.process_time() - t0)
    compare(runs["full"], runs["group-vertex"])
    joint, screen = runs["group-vertex"][:2]
    extra = []
    for L in range(1, 9):                               # joint LPs the screen refutes: in order of L
        kk = np.flatnonzero((joined.joint_box_mask & (np.uint64(1) << np.uint64(L - 1))) != 0)
        extra += pair_problems(decomp, system, Zs, Pairs(joined.joint_src[kk], joined.joint_dst[kk],
                                                         np.zeros(kk.size, bool)), L)
    extra = extra[:args.extra]
    print(f"load average {os.getloadavg()}", flush=True)
    report("joint LPs of the phase", time_lps(joint.problems, args.repeat))
    report("first joint LPs by L", time_lps(extra, args.repeat))
    report("projected LPs", time_lps(screen.solve_batch.problems[:args.projected], args.repeat))
    print(f"load average {os.getloadavg()}", flush=True)


if __name__ == "__main__":
    main()
