"""Benchmark: ``load_product`` of the 6-D drone's product system on a lifted building (a script, not a test).

Builds the product system of ``MAP`` lifted by ``DIVISIONS`` (the system of experiments/drone_scale.py)
into ``DIR`` if it is not there, **without the joint phase** (for this measurement only: the joint
LPs take hours on the building, docs/math/drone.md), saved without an inputs record. Then loads it
``--repeats`` times, each in a fresh process, with the problem given (built first in that process,
not timed), and prints one JSON line per load: seconds, RSS before, the peak during the load
(``VmHWM`` reset before it) and after, and a digest of everything loaded (edges, structure, tables,
verdicts). Each load imports tubejax from ``PYTHONPATH``, set to this checkout or, with ``--old ROOT``,
alternately to ``ROOT`` (another version's package: ``git archive main tubejax | tar -x -C ROOT``);
then the medians of each and whether their digests agree.

Usage
-----
python experiments/product_load.py conf/workspace/maps/building3d_small.txt 5,4,5 /tmp/small --old /tmp/old
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import tubejax
import tubejax.abstraction.product_abstraction as pa
from tubejax.abstraction.product_store import ProductProblem, load_product, save_product
from tubejax.model.geometry import Ball
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.system_kinds import double_integrator_lookahead
from tubejax.model.workspace.lookahead import lift_lookahead
from tubejax.model.workspace.voxelmap import parse_map
from tubejax.model.zshape.kinds import cross_sections

ROOT = Path(__file__).resolve().parents[1]


def problem(map_file: str, divisions: list):
    """``(decomposition, system, Z)`` of experiments/drone_scale.py."""
    decomp = lift_lookahead(parse_map(Path(map_file).read_text(), map_file), divisions)
    A, B = double_integrator_lookahead(3, 0.5, 2.0)
    system = LinearSystem(A=A.astype(float), B=B.astype(float), U=box_input_set(1.0, 3), W=Ball(6, 0.01))
    return decomp, system, cross_sections(decomp, "cell", 1.0)


def build(map_file: str, divisions: list, directory: str) -> None:
    """The product system without its joint phase, saved to ``directory`` (measurement only)."""
    pa.joint_pairs = lambda *args: ({}, {}, {}, 0)      # no joint LPs: this system is never committed
    decomp, system, Z = problem(map_file, divisions)
    save_product(pa.build_product_abstraction(decomp, system, Z=Z, L_max=8), directory)


def _status(field: str) -> float:
    return int(next(ln for ln in open("/proc/self/status") if ln.startswith(field)).split()[1]) / 1024


def digest(ps) -> str:
    """A SHA-256 prefix of the loaded system: edge arrays (with dtypes), structure, tables, verdicts."""
    h = hashlib.sha256()
    for a in (ps.src, ps.dst, ps.L, ps.margin, ps.variant, ps.structure.cell_factor):
        h.update(str(a.dtype).encode() + np.ascontiguousarray(a).tobytes())
    for t in ps.tables:
        h.update(t.feasible.tobytes() + t.margin.tobytes())
        for k in sorted(t.verdicts):
            v = t.verdicts[k]
            h.update(repr((k, v.status, v.margin, v.provenance, v.proof.level, v.proof.violation)).encode())
            h.update(b"".join(np.asarray(a).tobytes() for a in v.tube))
    for k in sorted(ps.joint):
        h.update(repr(k).encode() + b"".join(np.asarray(a).tobytes() for a in ps.joint[k].tube))
    h.update(repr((ps.L_max, ps.eps_min, sorted(ps.stats))).encode())
    return h.hexdigest()[:16]


def once(map_file: str, divisions: list, directory: str) -> dict:
    """One load in this process (the problem built first, not timed)."""
    P = ProductProblem(*problem(map_file, divisions))
    before = _status("VmRSS")
    Path("/proc/self/clear_refs").write_text("5")       # VmHWM := VmRSS: the peak of the load itself
    t = time.perf_counter()
    ps = load_product(directory, P)
    seconds = time.perf_counter() - t
    return {"code": str(Path(tubejax.__file__).parents[1]), "load_s": round(seconds, 3),
            "rss_before_mb": round(before), "peak_mb": round(_status("VmHWM")), "rss_after_mb": round(_status("VmRSS")),
            "edges": ps.n_edges, "digest": digest(ps), "load": os.getloadavg()[0]}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("map_file")
    ap.add_argument("divisions", help="velocity divisions per axis, e.g. 5,4,5")
    ap.add_argument("directory", help="the product system's directory (built there if missing)")
    ap.add_argument("--old", help="a folder holding another tubejax package, loaded alternately")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--once", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    divisions = [int(x) for x in a.divisions.split(",")]
    if a.once:
        print(json.dumps(once(a.map_file, divisions, a.directory)))
        return
    if not (Path(a.directory) / "product_transitions.npz").is_file():
        build(a.map_file, divisions, a.directory)
    print(f"load average {os.getloadavg()}", flush=True)
    runs: dict = {}
    for _ in range(a.repeats):
        for root in ([a.old] if a.old else []) + [str(ROOT)]:
            out = subprocess.run([sys.executable, __file__, a.map_file, a.divisions, a.directory, "--once"],
                                 env={**os.environ, "PYTHONPATH": root}, capture_output=True,
                                 text=True, check=True).stdout.strip().splitlines()[-1]
            print(out, flush=True)
            runs.setdefault(root, []).append(json.loads(out))
    for root, rs in runs.items():
        print(f"{root}: median {statistics.median(r['load_s'] for r in rs):.2f} s, peak "
              f"{statistics.median(r['peak_mb'] - r['rss_before_mb'] for r in rs):.0f} MB and after "
              f"{statistics.median(r['rss_after_mb'] - r['rss_before_mb'] for r in rs):.0f} MB over the RSS before")
    print(f"digests agree: {len({r['digest'] for rs in runs.values() for r in rs}) == 1}; "
          f"load average {os.getloadavg()}")


if __name__ == "__main__":
    main()
