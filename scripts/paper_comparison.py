"""The paper's Section V beside this project: the worked pair 1 -> 2 and the result counts.

    python scripts/paper_comparison.py                  # both parts, as Markdown tables
    python scripts/paper_comparison.py --part pair      # the pair 1 -> 2 only (about 2 s)
    python scripts/paper_comparison.py --part counts    # the transition counts only
    python scripts/paper_comparison.py --part pair --figure docs/img/worked-example-tube.png

Every number of docs/math/worked-example.md and of the results table of docs/math/paper.md is
printed by this script; tests/test_paper_comparison.py recomputes them with the functions below
and compares them with the pages, so the pages cannot drift from the code.

The pair: the cells labelled 1 and 2 of the project's paper map (conf/workspace/maps/paper.txt,
its substitute for the paper's Fig. 5), the paper's system (``A = I``, ``B = 0.5 I``, ``U`` the box
``|u_i| <= 1``, ``W`` the 2-norm ball of radius 0.2) and ``Z = [-1, 1]^2``. For each horizon
``L = 1 .. L_max`` it builds Problem 2 in its margin form (docs/math/margins.md#margin-form), reports
the LP's size and HiGHS's optimal margin ``t*``, and at the least ``L`` with ``t* >= 0`` the
optimal tube. It also solves the pair under the readings of the paper that the project does not
take (docs/math/paper.md#departures): the closed free-case test and the 1-norm input set, and
pairs of unit cells at other offsets on an open grid.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

import tubejax as tj
from tubejax.lp.evidence.verdict import highs_verdict
from tubejax.lp.declarations.tube_lp import build_tube_lp, tube_violation
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem, box_input_set, one_norm_input_set
from tubejax.model.zshape.kinds import make_z

ROOT = Path(__file__).resolve().parents[1]
PAPER_MAP = ROOT / "conf" / "workspace" / "maps" / "paper.txt"
#: Section V of the paper: the pair's horizon, the counts of its transition system, its run.
PAPER = {"L_12": 8, "states": 67, "transitions": 655, "seconds": 950, "runs": 50, "L_max": 10}


def paper_system(u_set: str = "box", w_set: str = "ball", radius: float = 0.2) -> LinearSystem:
    """``x+ = x + 0.5 u + w`` with ``U`` the box or the 1-norm ball of radius 1, and ``W`` the
    2-norm ball, the box (infinity-norm ball) or the 1-norm ball of ``radius``."""
    U = box_input_set(1.0, 2) if u_set == "box" else one_norm_input_set(1.0, 2)
    W = {"ball": lambda: Ball(2, radius),
         "box": lambda: Polytope.box([-radius, -radius], [radius, radius]),
         "one_norm": lambda: Polytope.from_vertices(radius * np.array([[0, -1], [1, 0], [0, 1], [-1, 0.0]]))}[w_set]()
    return LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=U, W=W)


def _least_L(decomp, system, i: int, j: int, L_max: int, obstacle_case: bool = False):
    """``(L, t*)`` of the least ``L <= L_max`` at which ``i -> j`` is an edge, else ``(None, nan)``.

    Each ``L`` is decided as an abstraction decides it (:func:`~tubejax.lp.evidence.verdict.highs_verdict`:
    HiGHS, its tube re-checked in float64, a margin near 0 decided in exact arithmetic);
    ``obstacle_case=True`` imposes ``S = P_i`` whatever the geometry says."""
    Z = make_z("box", decomp.cells[i])
    for L in range(1, L_max + 1):
        prob = pair_problem(decomp, system, Z, i, j, L)
        if obstacle_case:
            prob = dataclasses.replace(prob, safe=decomp.cells[i])
        v = highs_verdict(prob)
        if v.status == "edge":
            return L, v.margin
    return None, float("nan")


def worked_pair(L_max: int = 10) -> dict:
    """Problem 2 for the cells labelled 1 and 2 of the paper map, ``L = 1 .. L_max``.

    Returns
    -------
    dict
        ``source``, ``target`` (cell ids and vertices), ``obstacle_case``; ``sizes``: per ``L``
        ``(L, n_columns, n_rows, n_rows_per_family, t*)`` with ``n_columns`` the LP's variables
        ``p, eps, u`` plus ``t`` and ``n_rows`` its margin rows (C2, C3, C4; a box ``U`` and C1 are
        bounds); ``L_min`` and ``t_min`` (the least feasible ``L`` and its margin); ``tube``: HiGHS's
        optimal tube at ``L_min`` (``p (L, 2)``, ``eps (L,)``, ``u (L, 4, 2)``) and its float64
        violation; ``trailing``: the left faces ``p_l - eps_l`` of its sets; ``closed_test``: the
        least ``L`` when the pair is put in the obstacle case (the paper's closed test
        ``P_12 ∩ O = ∅``); ``one_norm_U``: the least ``L`` with ``U = {|u_1| + |u_2| <= 1}``
        (``None``: none up to 2 L_max).
    """
    decomp = tj.grid_map(PAPER_MAP).decomposition
    (i,), (j,) = decomp.cells_with_label("1"), decomp.cells_with_label("2")
    system = paper_system()
    Z = make_z("box", decomp.cells[i])
    sizes, found = [], None
    for L in range(1, L_max + 1):
        prob = pair_problem(decomp, system, Z, i, j, L)
        lp = build_tube_lp(prob)
        r = solve_margin_lp(lp)
        per_family = {name: int(np.prod(shape)) for name, shape in zip(lp.layout.names, lp.layout.shapes)}
        sizes.append((L, lp.G.shape[1] + 1, lp.G.shape[0] + lp.G_hard.shape[0], per_family, r.margin))
        if found is None and highs_verdict(prob).status == "edge":
            tube = lp.index.split(r.x)
            found = {"L_min": L, "t_min": r.margin, "tube": tube, "violation": tube_violation(prob, tube),
                     "trailing": tube.p[:, 0] - tube.eps}
    closed_L, _ = _least_L(decomp, system, i, j, L_max, obstacle_case=True)
    one_norm_L, _ = _least_L(decomp, paper_system(u_set="one_norm"), i, j, 2 * L_max)
    return {"source": (i, decomp.cells[i].vertices), "target": (j, decomp.cells[j].vertices),
            "obstacle_case": bool(decomp.obstacle_case(i, j)), "sizes": sizes, **(found or {"L_min": None}),
            "closed_test": closed_L, "one_norm_U": one_norm_L}


#: Offsets (columns, rows) of the target cell on an open grid, for :func:`offsets_table`.
OFFSETS = ((1, 0), (2, 0), (3, 0), (1, 1), (2, 1), (2, 2))


def offsets_table(L_max: int = 20) -> list:
    """The least ``L`` (``None``: none up to ``L_max``) from the top-left unit cell of an open 4 x 4
    grid to the cell at each offset of :data:`OFFSETS`, for ``U`` the box and the 1-norm ball and
    ``W`` the 2-norm, infinity-norm and 1-norm balls of radius 0.2: rows ``(offset, u_set, w_set, L)``."""
    decomp = tj.grid_map("....\n....\n....\n....").decomposition
    out = []
    for dx, dy in OFFSETS:
        for u_set in ("box", "one_norm"):
            for w_set in ("ball", "box", "one_norm"):
                L, _ = _least_L(decomp, paper_system(u_set, w_set), 0, 4 * dy + dx, L_max)
                out.append(((dx, dy), u_set, w_set, L))
    return out


#: The readings of the paper whose transition counts :func:`counts` gives: (name, u_set, w_set, L_max).
READINGS = (("the project's default", "box", "ball", 10),
            ("W the infinity-norm ball", "box", "box", 10),
            ("W the 1-norm ball", "box", "one_norm", 10),
            ("U the 1-norm ball", "one_norm", "ball", 10),
            ("L_max not tried (L < L_max)", "box", "ball", 9))


def counts() -> list:
    """``(name, n_cells, n_edges, L of 1 -> 2 or None)`` of the paper map under each of :data:`READINGS`,
    each a full verified abstraction (``tj.abstract`` with ``solver='highs'``)."""
    ws = tj.grid_map(PAPER_MAP)
    (i,), (j,) = ws.decomposition.cells_with_label("1"), ws.decomposition.cells_with_label("2")
    out = []
    for name, u_set, w_set, L_max in READINGS:
        ts = tj.abstract(ws, paper_system(u_set, w_set), L_max=L_max, solver="highs")
        k = ts.edge_index().get((i, j))
        out.append((name, ts.n_cells, ts.n_edges, None if k is None else ts.edges[k].L))
    return out


def _fmt(x: float) -> str:
    return f"{x:.6g}"


def print_pair(d: dict) -> None:
    i, Vi = d["source"]
    j, Vj = d["target"]
    print(f"cells: 1 = cell {i} {Vi.min(0).tolist()}..{Vi.max(0).tolist()}, "
          f"2 = cell {j} {Vj.min(0).tolist()}..{Vj.max(0).tolist()}, obstacle case: {d['obstacle_case']}\n")
    print("| L | columns | margin rows (safe / target / dynamics) | t* |")
    print("|---|---|---|---|")
    for L, cols, rows, fam, t in d["sizes"]:
        print(f"| {L} | {cols} | {rows} ({fam['safe']} / {fam['target']} / {fam['dynamics']}) | {_fmt(t)} |")
    print(f"\nleast L: {d['L_min']}, t* = {_fmt(d['t_min'])}, float64 violation {d['violation']:.1e}")
    tube = d["tube"]
    print("\n| ℓ | p_ℓ | ε_ℓ | left face p_ℓ,1 − ε_ℓ |")
    print("|---|---|---|---|")
    for ell in range(len(tube.eps)):
        print(f"| {ell + 1} | ({_fmt(tube.p[ell, 0])}, {_fmt(tube.p[ell, 1])}) | {_fmt(tube.eps[ell])} | "
              f"{_fmt(d['trailing'][ell])} |")
    print("\nvertex inputs u_k(ℓ), k = 1..4 (canonical order):")
    for ell in range(len(tube.eps)):
        print(f"  ℓ = {ell}: " + ", ".join(f"({_fmt(a)}, {_fmt(b)})" for a, b in tube.u[ell]))
    print(f"\nclosed free-case test (obstacle case): least L = {d['closed_test']}")
    print(f"U the 1-norm ball: least L = {d['one_norm_U']}")


def plot_pair(d: dict, path) -> None:
    """The pair's cells, their hull ``P_12``, the walls next to it and the tube ``Q_1 .. Q_L`` (PNG)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    (_, Vi), (_, Vj) = d["source"], d["target"]
    tube = d["tube"]
    fig, ax = plt.subplots(figsize=(6.4, 2.6))
    tj.plot.plot_workspace(tj.grid_map(PAPER_MAP).decomposition, ax=ax, labels=False)
    for lo, hi, style in ((Vi.min(0), Vj.max(0), dict(fill=False, lw=1.5, ec="0.2", ls="--")),
                          (Vi.min(0), Vi.max(0), dict(fc="tab:blue", alpha=0.15, ec="tab:blue")),
                          (Vj.min(0), Vj.max(0), dict(fc="tab:green", alpha=0.15, ec="tab:green"))):
        ax.add_patch(Rectangle(lo, *(np.asarray(hi) - lo), **style))
    for ell, (p, e) in enumerate(zip(tube.p, tube.eps), 1):
        ax.add_patch(Rectangle(p - e, 2 * e, 2 * e, fill=False, ec=plt.cm.viridis(ell / len(tube.eps)), lw=1.2))
        ax.text(p[0], p[1], f"$Q_{ell}$", ha="center", va="center", fontsize=7)
    ax.text(*(Vi.min(0) + [0.05, 0.85]), "$P_1$", fontsize=9)
    ax.text(*(Vj.min(0) + [0.05, 0.85]), "$P_2$", fontsize=9)
    ax.set_xlim(Vi.min(0)[0] - 0.1, Vj.max(0)[0] + 1.1)
    ax.set_ylim(Vi.min(0)[1] - 0.6, Vi.max(0)[1] + 0.1)
    ax.set_aspect("equal")
    ax.set_title(f"Cells 1 and 2 of the paper map, their hull $P_{{12}}$ (dashed), obstacles, "
                 f"the tube at L = {d['L_min']}", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--part", choices=("pair", "offsets", "counts", "all"), default="all")
    ap.add_argument("--figure", type=Path, help="also draw the pair's tube into this PNG")
    args = ap.parse_args()
    if args.part in ("pair", "all"):
        pair = worked_pair()
        print_pair(pair)
        if args.figure:
            plot_pair(pair, args.figure)
    if args.part in ("offsets", "all"):
        print("\n| offset | U | W | least L |\n|---|---|---|---|")
        for off, u_set, w_set, L in offsets_table():
            print(f"| {off} | {u_set} | {w_set} | {L} |")
    if args.part in ("counts", "all"):
        print("\n| reading | states | transitions | L of 1 → 2 |\n|---|---|---|---|")
        for name, n, e, L in counts():
            print(f"| {name} | {n} | {e} | {L} |")


if __name__ == "__main__":
    main()
