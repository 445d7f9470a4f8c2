"""The open-loop method with a non-box ``U`` on the batched engine against HiGHS: identical edges and
``L``, and the route of every LP (issue 46: C5 of a non-box ``U`` are the operator's hard rows).

For the corridor and paper maps (``r = 0.1``, ``L_max = 6``) and two non-box input sets (the 1-norm
``U`` of conf/system/integrator2d_l1.yaml; a pentagon with the paper map's coupled ``A``, ``B``),
builds the open-loop transition system with HiGHS and with ``pdhg_solver('openloop')`` and prints the
edge count, the provenance counts and the engine's route (PDHG status counts, LPs settled by
translation). With ``--json PATH`` it writes edges and provenance for a later comparison.

Usage::

    python scripts/check_openloop_hard_rows.py [--json out.json]

Exits 1 if any system differs from HiGHS's or an LP was sent to HiGHS unbatched.
"""

from __future__ import annotations

import argparse
import json
import sys

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.lp.evidence.verdict import highs_solver  # noqa: E402
from tubejax.lp.batch.batch_solver import pdhg_solver  # noqa: E402
from tubejax.model.geometry import Ball, Polytope  # noqa: E402
from tubejax.model.system import LinearSystem, one_norm_input_set  # noqa: E402
from tubejax.model.workspace.gridmap import load_grid_map  # noqa: E402

openloop_solve_batch = highs_solver("openloop")

PENTAGON = Polytope.from_vertices(np.array([[1.0, 0.2], [0.3, 1.0], [-0.8, 0.6], [-0.7, -0.9], [0.6, -0.8]]))
SYSTEMS = {"one_norm": dict(A=np.eye(2), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2)),
           "pentagon": dict(A=np.array([[1.0, 0.1], [-0.05, 0.95]]), B=np.array([[0.5, 0.1], [0.0, 0.4]]),
                            U=PENTAGON)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", default=None)
    a = ap.parse_args()
    out, ok = {}, True
    for name in ("corridor", "paper"):
        dec = load_grid_map(f"conf/workspace/maps/{name}.txt")
        for sname, kw in SYSTEMS.items():
            sysm = LinearSystem(W=Ball(2, 0.1), **kw)
            pdhg = pdhg_solver("openloop", pool=64, min_bucket=64, l_buckets=(6,), tail_width=None)
            runs = {s: build_abstraction(dec, sysm, L_max=6, method="openloop", solve_batch=solver, progress=False)
                    for s, solver in (("highs", openloop_solve_batch), ("pdhg", pdhg))}
            edges = {s: sorted([e.src, e.dst, e.L] for e in ts.edges) for s, ts in runs.items()}
            st = pdhg.stats
            batched = sum(st["status_counts"].values()) + st["translated_to_highs"] == st["n_lps"]
            same = edges["highs"] == edges["pdhg"]
            ok &= same and batched and st["highs_disagreements"] == 0
            print(f"{name:9s} {sname:9s} edges {len(edges['highs']):4d} identical {same}  all batched {batched}  "
                  f"PDHG {dict(st['status_counts'])}  provenance {dict(runs['pdhg'].stats['provenance'])}", flush=True)
            for s, ts in runs.items():
                out[f"{name}/{sname}/{s}"] = dict(edges=edges[s], provenance=dict(ts.stats["provenance"]))
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f)
    print("ALL IDENTICAL" if ok else "DIFFERENCES FOUND")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
