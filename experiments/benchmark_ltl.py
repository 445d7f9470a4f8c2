"""Ten common robotics LTL formulas on a ~1,000-cell rooms map: automaton, product and planning time.

python experiments/benchmark_ltl.py [--out DIR] [--rooms 4] [--size 8] [--lmax 10] [--runs N]
python experiments/benchmark_ltl.py --patterns 2000

The map is a grid of ``rooms x rooms`` rooms of ``size x size`` cells (walls one cell thick,
two-cell doors; 4 x 8: 32 x 32, 889 free cells), with a labelled region in up to nine rooms;
the abstraction (HiGHS, r = 0.2, ``L_max``, the spec tests' system) is built once and saved
under ``--out``. For each formula (the specification-pattern literature:
surveillance, sequenced patrolling, response, reach-and-stay, avoidance) the table gives Spot's
Büchi automaton states, the product's nodes and arcs, and the seconds to plan (automaton,
product, lasso). With ``--runs N`` every plan is simulated ``N`` adversarial runs over two
cycles and every run's words are checked by Spot (``runs_satisfying_spec``).

``--patterns N``: instead, ``N`` adversarial runs (three cycles) of each of five patterns
(surveillance, response, reach-and-stay, sequenced patrolling, avoidance) on the small maps of
the spec tests, every run's words checked by Spot.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

#: The ten formulas: (pattern, formula).
FORMULAS = [
    ("surveillance (2 rooms)", "GF l1 & GF l2"),
    ("surveillance (4 rooms)", "GF l1 & GF l2 & GF l3 & GF l4"),
    ("surveillance + avoid", "GF l1 & GF l4 & G !l5"),
    ("sequenced patrol (3)", "G F(l1 & F(l2 & F l3))"),
    ("sequenced patrol (4) + avoid", "G F(l1 & F(l2 & F(l3 & F l4))) & G !l5"),
    ("response", "G(l2 -> F l3) & GF l2"),
    ("response + avoid", "G(l1 -> F(l4)) & GF l1 & G(!l5 & !l6)"),
    ("reach-avoid then patrol", "F l6 & GF l7 & GF l8"),
    ("strict order (1 before 2)", "(!l2 U l1) & GF l2 & GF l1"),
    ("recurrence with timing", "GF(l3 & X !l3) & GF l4"),
]


def rooms_map(rooms: int = 4, size: int = 8) -> str:
    """A ``rooms*size`` square grid: walls on the room borders, a two-cell door in each inner wall, labels."""
    n = rooms * size
    g = np.full((n, n), ".", dtype="<U1")
    for k in range(1, rooms):
        g[k * size - 1, :] = "#"
        g[:, k * size - 1] = "#"
    for k in range(1, rooms):
        for r in range(rooms):
            mid = r * size + size // 2 - 1
            g[k * size - 1, mid:mid + 2] = "."             # horizontal walls: a door in every room
            g[mid:mid + 2, k * size - 1] = "."
    labels = "123456789"[:rooms * rooms]
    spots = [(r, c) for r in range(rooms) for c in range(rooms)][:len(labels)]
    for lab, (r, c) in zip(labels, spots):
        g[r * size + 1, c * size + 1] = lab
        g[r * size + 1, c * size + 2] = lab
    return "\n".join("".join(row) for row in g) + "\n"


def abstraction(out: Path, rooms: int, size: int, lmax: int):
    from tubejax.abstraction import build_abstraction
    from tubejax.model.workspace.gridmap import load_grid_map
    from tubejax.transitions.transition_system import TransitionSystem

    out.mkdir(parents=True, exist_ok=True)
    if (out / "transitions.json").exists():
        return TransitionSystem.load(out)
    (out / "rooms.txt").write_text(rooms_map(rooms, size))
    d = load_grid_map(out / "rooms.txt")
    t = time.perf_counter()
    ts = build_abstraction(d, _system(), L_max=lmax, progress=True)
    print(f"abstraction: {ts.n_cells} cells, {ts.n_edges} edges, {time.perf_counter() - t:.1f} s")
    ts.save(out)
    return ts


def _system():
    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set

    return LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))


def patterns(runs: int, out: Path) -> None:
    """``runs`` adversarial runs of five formula patterns, checked by Spot (module docstring)."""
    from tubejax.abstraction import build_abstraction
    from tubejax.analyses.control import SimulationRuns
    from tubejax.analyses.spec import plan_ltl, simulate_spec
    from tubejax.model.workspace.boxgrid import box_grid
    from tubejax.model.workspace.gridmap import load_grid_map

    out.mkdir(parents=True, exist_ok=True)
    (out / "avoid.txt").write_text("1.4.2\n.###.\n3....\n")
    avoid = build_abstraction(load_grid_map(out / "avoid.txt"), _system(), L_max=10, progress=False)
    home = build_abstraction(box_grid([0, 0], [4, 4], [4, 4], labels={"h": ([0, 0], [2, 2]), "b": ([3, 3], [4, 4]),
                                                                      "c": ([2, 0], [3, 1])}),
                             _system(), L_max=10, progress=False)
    cases = [("surveillance", avoid, 0, "GF l3 & GF l2 & G !l4"),
             ("response", avoid, 0, "G(l3 -> F l2) & GF l3"),
             ("reach-and-stay", home, 15, "F G lh & G !lc & G(lb -> F lh)"),
             ("sequenced patrolling", avoid, 0, "G F(l3 & F(l2 & F l1))"),
             ("avoidance", avoid, 0, "G !l4 & GF l3 & F l2")]
    print("| pattern | formula | lasso steps | runs satisfying (Spot) | tube exits | avoided-region entries | s |")
    print("|---|---|---|---|---|---|---|")
    for name, ts, start, f in cases:
        t = time.perf_counter()
        sp = plan_ltl(ts, start, f, cycles=3)
        s = simulate_spec(ts, sp, SimulationRuns(n_runs=runs, mode="adversarial", seed=0)).summary()
        print(f"| {name} | `{f}` | {sp.lasso['prefix_steps']} + 3 x {sp.lasso['cycle_steps']} | "
              f"{s['runs_satisfying_spec']} / {s['runs']} | {s['tube_exits']} | {s['avoided_region_entries']} | "
              f"{time.perf_counter() - t:.1f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="outputs/benchmark_ltl")
    ap.add_argument("--rooms", type=int, default=4)
    ap.add_argument("--size", type=int, default=8)
    ap.add_argument("--lmax", type=int, default=10)
    ap.add_argument("--runs", type=int, default=0)
    ap.add_argument("--patterns", type=int, default=0)
    args = ap.parse_args()
    if args.patterns:
        patterns(args.patterns, Path(args.out))
        return
    from tubejax.analyses.control import SimulationRuns
    from tubejax.analyses.spec import plan_ltl, simulate_spec

    ts = abstraction(Path(args.out), args.rooms, args.size, args.lmax)
    start = ts.decomposition.cells_with_label("9")[0]
    print(f"map: {ts.n_cells} cells, {ts.n_edges} edges; start cell {start} (region 9)\n")
    print("| pattern | formula | Büchi states (det.) | product nodes | product arcs | lasso steps (prefix + cycle) "
          "| automaton s | plan s |" + (" runs satisfying |" if args.runs else ""))
    print("|---|---|---|---|---|---|---|---|" + ("---|" if args.runs else ""))
    for name, f in FORMULAS:
        t = time.perf_counter()
        try:
            sp = plan_ltl(ts, start, f, cycles=2)
        except ValueError as exc:
            print(f"| {name} | `{f}` | refused: {exc} |")
            continue
        sec = time.perf_counter() - t
        st = sp.stats
        row = (f"| {name} | `{f}` | {st['buchi_states']} ({'yes' if st['buchi_deterministic'] else 'no'}) | "
               f"{st['product_nodes']:,} | {st['product_arcs']:,} | {st['prefix_steps']} + {st['cycle_steps']} | "
               f"{st['automaton_seconds']:.3f} | {sec:.2f} |")
        if args.runs:
            s = simulate_spec(ts, sp, SimulationRuns(n_runs=args.runs, mode="adversarial", seed=0)).summary()
            row += f" {s['runs_satisfying_spec']} / {s['runs']} |"
        print(row, flush=True)


if __name__ == "__main__":
    main()
