"""Benchmark: the product path against one joint 6-D LP of the product family per pair (a script, not a test).

Lifts a voxel map by look-ahead divisions (the drone of conf/system/drone6d.yaml: dt 0.5, beta 2,
|a| <= 1, W a 0.01 ball), builds the product system (``build_product_abstraction``, ``zshape='cell'``)
and re-solves sampled pairs with :func:`tubejax.verify.product_lp.product_lp_margin`: the tube LP of
the product family for the full 6-D pair, written vertex by vertex from the data and solved by SciPy's
HiGHS, independent of the factor LPs and the join (docs/math/product.md). The safe set is the one the
product path uses for the pair's factor edges: the bounding box of ``P_i u P_j`` when it meets no
obstacle, else ``P_i``. For each pair the least ``L`` at which that LP is feasible must be the system's
(``None`` for a non-edge); a pair whose margin comes within ``1e-7`` of 0 at some ``L`` is counted as too
close to call in floats (:data:`tubejax.verify.product_check.COMPLETE_TOL`). Sampled (seed 0): ``--edges`` of the factor edges and ``--non-edges`` pairs
without an edge whose target lies within one unit of the source in every position axis (far pairs are
trivially infeasible). Joint edges (blocked box, free hull: the paper's safe set) are not sampled.
Prints one Markdown row.

Usage
-----
python experiments/product_family_check.py conf/workspace/maps/building3d_tiny.txt 3,3,3 --edges 150 --non-edges 150
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from tubejax.abstraction.product_abstraction import JOINT, build_product_abstraction  # noqa: E402
from tubejax.model.geometry import Ball  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.system_kinds import double_integrator_lookahead  # noqa: E402
from tubejax.model.workspace.lookahead import lift_lookahead  # noqa: E402
from tubejax.model.workspace.voxelmap import parse_map  # noqa: E402
from tubejax.verify.product_check import least_product_family_L  # noqa: E402

HEADER = ("| map | divisions | cells | edges | L_max | pairs checked (edges + non-edges) | mismatches | "
          "too close | seconds |")
POSITION_AXES = [0, 2, 4]


def sample_pairs(ps, n_edges: int, n_non_edges: int, seed: int = 0) -> list:
    """``n_edges`` factor edges and ``n_non_edges`` near non-edges (module docstring), as ``(i, j)``."""
    rng = np.random.default_rng(seed)
    lo, hi = ps.decomposition.cell_boxes()
    factor = np.flatnonzero(ps.variant != JOINT)
    pick = np.sort(rng.choice(factor, min(n_edges, factor.size), replace=False))
    pairs = [(int(ps.src[k]), int(ps.dst[k])) for k in pick]
    has = set(zip(ps.src.tolist(), ps.dst.tolist()))
    p_lo, p_hi = lo[:, POSITION_AXES], hi[:, POSITION_AXES]
    near = []
    for i in range(ps.n_cells):
        js = np.flatnonzero(np.all(p_lo <= p_hi[i] + 1, axis=1) & np.all(p_hi >= p_lo[i] - 1, axis=1))
        near += [(i, int(j)) for j in js.tolist() if j != i and (i, j) not in has]
    pick = np.sort(rng.choice(len(near), min(n_non_edges, len(near)), replace=False))
    return pairs + [near[k] for k in pick.tolist()]


def run(map_file: str, divisions: list, L_max: int = 8, n_edges: int = 150, n_non_edges: int = 150) -> dict:
    """Build the product system and check the sampled pairs (module docstring)."""
    decomp = lift_lookahead(parse_map(Path(map_file).read_text(), map_file), divisions)
    A, B = double_integrator_lookahead(3, 0.5, 2.0)
    system = LinearSystem(A=A.astype(float), B=B.astype(float), U=box_input_set(1.0, 3), W=Ball(6, 0.01))
    ps = build_product_abstraction(decomp, system, zshape="cell", L_max=L_max)
    t0 = time.perf_counter()
    have = {(int(i), int(j)): int(L) for i, j, L in zip(ps.src, ps.dst, ps.L)}
    pairs = sample_pairs(ps, n_edges, n_non_edges)
    mismatches, close = [], 0
    for n, (i, j) in enumerate(pairs):
        L, c = least_product_family_L(ps, i, j)
        close += int(c)
        if L != have.get((i, j)) and not c:
            mismatches.append((i, j, L, have.get((i, j))))
            print(f"pair {i}->{j}: the product-family LP gives L={L}, the system L={have.get((i, j))}",
                  file=sys.stderr)
        if (n + 1) % 50 == 0:
            print(f"{n + 1} of {len(pairs)} pairs, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    return {"map": Path(map_file).stem, "divisions": list(divisions), "cells": decomp.n_cells, "edges": len(ps.src),
            "L_max": L_max, "edges_checked": min(n_edges, int(np.sum(ps.variant != JOINT))),
            "checked": len(pairs), "mismatches": mismatches, "close": close, "seconds": time.perf_counter() - t0}


def row(r: dict) -> str:
    """The row of :data:`HEADER`."""
    return (f"| {r['map']} | {'x'.join(map(str, r['divisions']))} | {r['cells']:,} | {r['edges']:,} | {r['L_max']} | "
            f"{r['checked']:,} ({r['edges_checked']:,} + {r['checked'] - r['edges_checked']:,}) | "
            f"{len(r['mismatches'])} | {r['close']} | {r['seconds']:.0f} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("map_file")
    ap.add_argument("divisions", help="look-ahead divisions per axis, e.g. 3,3,3")
    ap.add_argument("--L-max", type=int, default=8)
    ap.add_argument("--edges", type=int, default=150, help="factor edges sampled")
    ap.add_argument("--non-edges", type=int, default=150, help="near pairs without an edge sampled")
    args = ap.parse_args(argv)
    r = run(args.map_file, [int(x) for x in args.divisions.split(",")], args.L_max, args.edges, args.non_edges)
    print(HEADER)
    print("|" + "---|" * (HEADER.count("|") - 1))
    print(row(r))
    return 1 if r["mismatches"] else 0


if __name__ == "__main__":
    sys.exit(main())
