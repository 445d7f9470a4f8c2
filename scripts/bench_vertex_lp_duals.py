"""Vertex-LP pruning with and without reused duals, side by side (candidates only).

    python scripts/bench_vertex_lp_duals.py                 # the 4-D double integrator, 4x4x4x4
    python scripts/bench_vertex_lp_duals.py --divisions 4444,5555

For each grid (``conf/workspace/boxgrid4d.yaml`` divided as given, ``conf/system/double_integrator.yaml``,
a ball ``W``), builds the candidates twice: with refuting duals reused across pairs of the same
shape (the default, :data:`tubejax.abstraction.vertex_lp._CERTIFICATES` per row structure) and
with none kept (every vertex LP solved). Prints the vertex LPs solved, the horizons dropped by a
reused dual, the seconds of the vertex-LP rule, and whether the kept instances are the same.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import yaml

from tubejax.abstraction import vertex_lp
from tubejax.abstraction.candidates import build_candidates
from tubejax.model.geometry import Ball
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import box_grid

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--divisions", default="4444", help="comma-separated cells per axis, e.g. 4444,5555")
    ap.add_argument("--radius", type=float, default=0.02, help="radius of the disturbance ball W")
    ap.add_argument("--L-max", type=int, default=8)
    args = ap.parse_args()
    ws = yaml.safe_load((ROOT / "conf/workspace/boxgrid4d.yaml").read_text())
    cfg = yaml.safe_load((ROOT / "conf/system/double_integrator.yaml").read_text())
    system = LinearSystem(A=np.array(cfg["A"], float), B=np.array(cfg["B"], float),
                          U=box_input_set(cfg["U"]["bound"], 2), W=Ball(4, args.radius))
    kept = vertex_lp._CERTIFICATES
    for div in args.divisions.split(","):
        decomp = box_grid(ws["lower"], ws["upper"], [int(c) for c in div],
                          obstacles=[tuple(o) for o in ws["obstacles"]], name=f"grid {div}")
        res = {}
        for name, cap in (("reused duals", kept), ("every LP solved", 0)):
            vertex_lp._CERTIFICATES = cap
            t = time.perf_counter()
            c = build_candidates(decomp, system, args.L_max)
            res[name] = c
            print(f"{div} {name:>16}: cells {decomp.n_cells}, vertex LPs {c.stats['n_vertex_lps']:,}, "
                  f"dropped by a reused dual {c.stats['n_vertex_duals_reused']:,}, "
                  f"vertex-LP rule {c.stats['seconds_vertex_lp']:.1f} s, "
                  f"dropped {c.pruned['vertex_lp_infeasible']:,}, candidates {time.perf_counter() - t:.1f} s",
                  flush=True)
        vertex_lp._CERTIFICATES = kept
        a, b = res.values()
        same = all(np.array_equal(getattr(a, f), getattr(b, f)) for f in ("src", "dst", "keep"))
        print(f"{div} same kept instances: {same}", flush=True)


if __name__ == "__main__":
    main()
