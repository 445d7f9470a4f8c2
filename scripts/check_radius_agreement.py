"""One-off check: the transition system derived from ONE radius solve (rho* of every candidate,
HiGHS deciding where a radius lies within [lower, upper]) equals build_abstraction's at
several radii (issue 12's agreement target; the app that does this for real comes later).

Usage: python scripts/check_radius_agreement.py conf/workspace/maps/corridor.txt
"""
import numpy as np, jax, sys
jax.config.update("jax_enable_x64", True)
from tubejax.workspace.gridmap import load_grid_map
from tubejax.system import LinearSystem, box_input_set
from tubejax.geometry import Ball
from tubejax.lp.formulations.zshape import make_z
from tubejax.problem import pair_problem
from tubejax.zshape.learn import candidate_pairs
from tubejax.abstraction import build_abstraction
from tubejax.lp.solvers.batched import PdhgBatchSolver
from tubejax.lp.formulations.radius.pdhg import radius_pdhg_solver
from tubejax.lp.formulations.radius.dense import radius_edge_verdict
mp = sys.argv[1] if len(sys.argv) > 1 else "conf/workspace/maps/corridor.txt"
dec = load_grid_map(mp)
sysm = LinearSystem(np.eye(2), 0.5*np.eye(2), box_input_set(1.0, 2), Ball(2, 0.2))
_, keep = candidate_pairs(dec, LinearSystem(sysm.A, sysm.B, sysm.U, Ball(2, 0.0)), 10)
Z = [make_z("box", c) for c in dec.cells]
c = np.argwhere(keep)
probs = [pair_problem(dec, sysm, Z[i], int(i), int(j), int(L)+1) for i, j, L in c]
res = radius_pdhg_solver("tube").optimise(probs)
ms = PdhgBatchSolver()
for r in (0.0, 0.05, 0.1, 0.2, 0.25, 0.3):
    s_r = LinearSystem(sysm.A, sysm.B, sysm.U, Ball(2, r))
    ts = build_abstraction(dec, s_r, L_max=10, solve_batch=ms, progress=False)
    want = {(e.src, e.dst): e.L for e in ts.edges}
    # derived: min L with rho* >= r; near ties (lower < r <= upper) decided by HiGHS
    got, ties = {}, 0
    for k, (i, j, L) in enumerate(c):
        i, j, L = int(i), int(j), int(L) + 1
        if (i, j) in got and got[(i, j)] <= L:
            continue
        if res.lower[k] >= r + 1e-9:
            ok = True
        elif res.upper[k] < r:
            ok = False
        else:
            ties += 1
            ok = radius_edge_verdict(probs[k], Ball(2, 1.0), r).status == "edge"
        if ok:
            got[(i, j)] = min(L, got.get((i, j), 99))
    print(mp.split("/")[-1], "r", r, "abstraction edges", len(want), "derived", len(got), "identical", want == got, "HiGHS ties", ties)
