"""The product path's joint edges, side by side: CPU time per joint LP, from build to proved verdict.

Each joint edge of a ``drone_scale.py --edges FILE`` list (``[src, dst, L, margin]`` rows of
building3d_small lifted by ``--divisions``) is posed again as its joint tube problem and decided as the
joint phase decides it (:class:`~tubejax.abstraction.joint_duals.DualReuseSolver` with the group-vertex
LPs: build, HiGHS, verdict and exact proof). Runs this file as a worker under two checkouts in turn
(``--old``, ``--new``), alternating, each run in a fresh process (cold caches, as in a run), and prints the
median over ``--runs`` runs of the mean CPU milliseconds per edge, their ratio and the load average. Both
checkouts must give the same verdicts: status, margin (``float.hex``), proof level and provenance (checked).

Usage::

    python experiments/drone_scale.py conf/workspace/maps/building3d_small.txt 5,4,5 --joint-sample 1500 \\
        --edges /tmp/edges.json
    python scripts/bench_joint_edges.py /tmp/edges.json --old ../base --new . --runs 3
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAP = Path("conf") / "workspace" / "maps" / "building3d_small.txt"


def worker(edges_file: str, divisions: str) -> dict:
    """Decide every joint edge of ``edges_file`` once (this checkout): CPU seconds and verdicts."""
    import numpy as np

    from tubejax.abstraction.group_vertex_lp import solve_by_group_vertices
    from tubejax.abstraction.joint_duals import DualReuseSolver
    from tubejax.model.geometry import Ball
    from tubejax.model.problem import Pairs, pair_problems
    from tubejax.model.system import LinearSystem, box_input_set
    from tubejax.model.system_kinds import double_integrator_lookahead
    from tubejax.model.workspace.lookahead import lift_lookahead
    from tubejax.model.workspace.voxelmap import parse_map
    from tubejax.model.zshape.kinds import cross_sections

    decomp = lift_lookahead(parse_map(MAP.read_text(), str(MAP)), [int(d) for d in divisions.split(",")])
    A, B = double_integrator_lookahead(3, 0.5, 2.0)
    system = LinearSystem(A=A.astype(float), B=B.astype(float), U=box_input_set(1.0, 3), W=Ball(6, 0.01))
    Zs = cross_sections(decomp, "cell", 1.0)
    probs = [pair_problems(decomp, system, Zs, Pairs(np.array([i]), np.array([j]), np.zeros(1, bool)), L, 0.0)[0]
             for i, j, L, _ in json.loads(Path(edges_file).read_text())]
    solver = DualReuseSolver(solve_by_group_vertices)
    t0 = time.process_time()
    out = [solver.verdict(p) for p in probs]
    cpu = time.process_time() - t0
    return {"n": len(probs), "cpu": cpu,
            "verdicts": [(v.status, float(v.margin).hex(), getattr(v.proof, "level", None), v.provenance) for v in out]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("edges", help="a drone_scale.py --edges file")
    ap.add_argument("--old", help="the checkout to compare against")
    ap.add_argument("--new", default=str(ROOT), help="this checkout (default)")
    ap.add_argument("--divisions", default="5,4,5", help="look-ahead slabs per axis of the --edges run")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        print(json.dumps(worker(a.edges, a.divisions)))
        return 0
    trees = {"old": a.old, "new": a.new} if a.old else {"new": a.new}
    edges = str(Path(a.edges).resolve())
    ms: dict = {k: [] for k in trees}
    verdicts: dict = {}
    for r in range(a.runs):
        for name, tree in trees.items():
            env = dict(os.environ, PYTHONPATH=str(Path(tree).resolve()))
            cmd = [sys.executable, str(Path(tree).resolve() / "scripts" / "bench_joint_edges.py"), edges,
                   "--divisions", a.divisions, "--worker"]
            if not (Path(tree) / "scripts" / "bench_joint_edges.py").exists():
                cmd[1] = str(Path(__file__).resolve())
            got = json.loads(subprocess.run(cmd, env=env, cwd=str(Path(tree).resolve()), check=True,
                                            capture_output=True, text=True).stdout.strip().splitlines()[-1])
            ms[name].append(1e3 * got["cpu"] / max(got["n"], 1))
            verdicts.setdefault(name, got["verdicts"])
            print(f"run {r + 1} {name}: {ms[name][-1]:.1f} ms per edge ({got['n']} edges), "
                  f"load {os.getloadavg()[0]:.1f}", flush=True)
    med = {k: statistics.median(v) for k, v in ms.items()}
    print(" ".join(f"{k} {v:.1f} ms" for k, v in med.items()) + " per joint edge (CPU, medians)")
    if a.old:
        same = verdicts["old"] == verdicts["new"]
        print(f"ratio old / new {med['old'] / med['new']:.2f}; verdicts identical: {same}")
        return 0 if same else 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
