"""Issue 13's table: transitions per cross-section Z, learned Z against box / cell / diamond / regular,
as fractions of exact2d, with configuration-constrained tubes (facet offsets as LP variables) beside.

Benchmarks (r = 0.2 and L_max = 10 unless said): the corridor and the paper map with
``integrator2d_l1``; the triangulated polygon workspace ``rooms`` with ``integrator2d``; a
non-identity A (``conf/system/custom.yaml``: A = [[1, 0.1], [-0.1, 1]], U a diamond) on the paper
map; the 4-D double integrator (``boxgrid4d``, r = 0.02, L_max = 8, no exact2d).

Per benchmark: each applicable fixed Z (``build_abstraction``, HiGHS, timed); exact2d; then

* ``learned`` (one Z per cell shape): :func:`tubejax.analyses.zshape.learn_z` started per shape from the
  best of the applicable fixed kinds (multi-start), candidates = exact2d's edges in 2-D (they
  contain every tube edge, tested) or every unpruned pair, each at its last unpruned horizon
  (``paper_custom_A``: at its best one, the expanding A makes long horizons worse); the abstraction with that Z
  (``use_z_table`` + the unchanged ``build_abstraction``: HiGHS, float64 re-check, exact proofs);
* ``learned_pair`` (one Z per pair) started from the learned Z, and Algorithm 2 with it
  (:func:`tubejax.analyses.zshape.pair_abstraction`, same verification);
* CCP tubes with the box's 4 and an octagon's 8 normals (2-D), on exact2d's pairs from exact2d's
  horizon on (no tube edge lies outside them).

Every tube edge is checked to be an exact2d edge with ``L >= L_exact``; the learned Z tables are
written to ``--out``. Usage::

    python scripts/learned_z_table.py                       # all benchmarks (~15 min on 2 cores)
    python scripts/learned_z_table.py --only corridor_l1 --out out/learned_z
"""

from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path

import jax
import numpy as np
import yaml

jax.config.update("jax_enable_x64", True)

from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.reachability.exact2d import exact_edges  # noqa: E402
from tubejax.inputs import ProblemInputs  # noqa: E402
from tubejax.analyses.zshape import (LearnOptions, learn_z, pair_abstraction, table_from_learned,  # noqa: E402
                                     use_z_table)
from tubejax.analyses.zshape.ccp import box_normals, ccp_abstraction, octagon_normals  # noqa: E402
from tubejax.model.zshape.z_table import cell_shape_key  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CONF = ROOT / "conf"

#: name: (system, workspace, radius, L_max, fixed kinds, learning options, CCP)
BENCHMARKS = {
    "corridor_l1": ("integrator2d_l1", "corridor", 0.2, 10, ("box", "cell", "diamond", "regular", "chamfer"),
                    dict(steps=30, learning_rate=0.05), True),
    "paper_l1": ("integrator2d_l1", "paper", 0.2, 10, ("box", "cell", "diamond", "regular", "chamfer"),
                 dict(steps=30, learning_rate=0.05), True),
    "rooms": ("integrator2d", "rooms", 0.2, 10, ("cell", "regular", "chamfer"),
              dict(steps=20, learning_rate=0.1), True),
    "paper_custom_A": ("custom", "paper", 0.2, 10, ("box", "cell", "diamond", "regular", "chamfer"),
                       dict(steps=30, learning_rate=0.05, horizon="best"), True),
    "double_integrator": ("double_integrator", "boxgrid4d", 0.02, 8, ("box", "cell"),
                          dict(steps=15, learning_rate=0.05), False),
}


def load(system: str, workspace: str, radius: float):
    """Decomposition and system from the conf/ presets (validated by tubejax.inputs)."""
    ws = yaml.safe_load((CONF / "workspace" / f"{workspace}.yaml").read_text())
    sy = yaml.safe_load((CONF / "system" / f"{system}.yaml").read_text())
    sy = {k: v for k, v in sy.items() if k not in ("dt", "beta")}      # descriptive only
    pi = ProblemInputs.from_dict({"workspace": ws, "system": sy,
                                  "disturbance": {"kind": "ball", "radius": radius}}, search_dirs=[ROOT])
    return pi.build_decomposition(), pi.build_system()


def within_exact(edges, exact) -> bool:
    return all((i, j) in exact and L >= exact[(i, j)][0] for i, j, L in edges)


def run(name: str, out: Path) -> dict:
    system_name, ws, r, L_max, kinds, learn_kw, ccp = BENCHMARKS[name]
    decomp, system = load(system_name, ws, r)
    row = {"benchmark": name, "system": system_name, "workspace": ws, "cells": decomp.n_cells, "fixed": {}}
    exact = exact_edges(decomp, system, L_max) if decomp.dim == 2 else None
    row["exact2d"] = None if exact is None else len(exact)
    fixed_seconds = {}
    for k in kinds:
        t0 = time.perf_counter()
        ts = build_abstraction(decomp, system, zshape=k, L_max=L_max, progress=False)
        fixed_seconds[k] = time.perf_counter() - t0
        row["fixed"][k] = ts.n_edges
        if exact is not None:
            assert within_exact([(e.src, e.dst, e.L) for e in ts.edges], exact), (name, k)
    best_kind = max(kinds, key=lambda k: row["fixed"][k])
    pairs = None if exact is None else np.array(sorted(exact), dtype=int).reshape(-1, 2)
    opts = LearnOptions(**learn_kw, L_max=L_max)
    same_count = [k for k in kinds if k != "chamfer"]      # chamfer (2 n_i vertices) is its own family: the app's
    res = learn_z(decomp, system, mode="learned", init=same_count, options=opts, progress=True,
                  pairs=pairs)                             # init=best learns it too (README); here n_i-vertex Z only
    table = table_from_learned(res, decomp, {"benchmark": name, "init": same_count, "options": opts._asdict()})
    table.save(out / f"{name}_learned_z.json")
    t0 = time.perf_counter()
    with use_z_table(table):
        ts = build_abstraction(decomp, system, zshape="learned", L_max=L_max, progress=False)
    learned_abs_s = time.perf_counter() - t0
    assert np.all(ts.verify() <= 1e-9)
    edges = [(e.src, e.dst, e.L) for e in ts.edges]
    row["learned"] = ts.n_edges
    row["learned_proof"] = dict(ts.stats["proof"])
    row["learned_within_exact2d"] = None if exact is None else within_exact(edges, exact)
    row["learn_seconds"] = res.seconds
    row["learned_abstraction_seconds"] = learned_abs_s
    row["fixed_seconds"] = fixed_seconds
    row["time_ratio"] = res.seconds / fixed_seconds[best_kind]
    row["learn_lps"] = res.n_lps
    row["learn_history"] = [(h["step"], round(h["objective"], 3), h["certified"]) for h in res.history]
    row["learned_z"] = res.z.tolist() if len(res.z) <= 4 else f"{len(res.z)} shapes (see the json)"
    # one Z per pair, started from the shared learned Z
    shared = {int(g): P for g, P in zip(res.group_cells, res.polytopes())}
    key_of = {}
    for g, P in shared.items():
        key_of[cell_shape_key(decomp.cells[g].vertices)] = P
    init = lambda i, j: key_of[cell_shape_key(decomp.cells[i].vertices)]            # noqa: E731
    resp = learn_z(decomp, system, mode="learned_pair", init=init, options=opts, progress=True,
                   pairs=np.array(sorted({tuple(map(int, p)) for p in res.pairs}), dtype=int))
    Zp = {(int(i), int(j)): P for (i, j), P in zip(resp.pairs, resp.polytopes())}
    table_from_learned(resp, decomp, {"benchmark": name}).save(out / f"{name}_learned_pair_z.json")
    pa = pair_abstraction(decomp, system, lambda i, j: Zp.get((i, j)) or key_of.get(cell_shape_key(decomp.cells[i].vertices)),
                          L_max=L_max)
    assert np.all(pa.verify() <= 1e-9)
    row["learned_pair"] = pa.stats["n_edges"]
    row["learned_pair_proof"] = pa.stats["proof"]
    row["learned_pair_within_exact2d"] = None if exact is None else within_exact(
        [(e.src, e.dst, e.L) for e in pa.edges], exact)
    row["learn_pair_seconds"] = resp.seconds
    if ccp and exact is not None:
        for tag, N in (("ccp_box", box_normals()), ("ccp_octagon", octagon_normals())):
            t0 = time.perf_counter()
            found = ccp_abstraction(decomp, system, N, L_max=L_max, exact=exact)
            row[tag] = len(found)
            row[f"{tag}_seconds"] = time.perf_counter() - t0
            assert within_exact([(i, j, L) for (i, j), (L, _) in found.items()], exact)
    return row


def fmt(row: dict) -> str:
    ex = row["exact2d"]

    def cell(n):
        if n is None:
            return "—"
        return f"{n} ({100 * n / ex:.0f} %)" if ex else str(n)
    fixed = " | ".join(cell(row["fixed"].get(k)) for k in ("box", "cell", "diamond", "regular", "chamfer"))
    return (f"| {row['benchmark']} | {ex if ex is not None else '—'} | {fixed} | {cell(row['learned'])} | "
            f"{cell(row['learned_pair'])} | {cell(row.get('ccp_box'))} | {cell(row.get('ccp_octagon'))} | "
            f"{row['time_ratio']:.1f}x |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", default=",".join(BENCHMARKS), help="comma-separated benchmark names")
    ap.add_argument("--out", default="outputs/learned_z", help="where the learned Z tables and rows go")
    a = ap.parse_args()
    logging.basicConfig(level=logging.WARNING)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in a.only.split(","):
        row = run(name, out)
        rows.append(row)
        (out / f"{name}.json").write_text(json.dumps(row, indent=1))
        print(fmt(row), flush=True)
    print("\n| benchmark | exact2d | box | cell | diamond | regular | chamfer | learned | learned_pair | CCP box | "
          "CCP octagon | learning time / fixed |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for row in rows:
        print(fmt(row))


if __name__ == "__main__":
    main()
