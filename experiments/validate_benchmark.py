"""How long validating a decomposition takes (tubejax.model.workspace.validate), by size.

Grid maps of rooms-and-corridors style (walls every 10 squares with doors, 5 % random
obstacles, from a seed) and 4-D box grids with a central obstacle; for each size the
minimum over ``--repeats`` runs of :func:`validate_decomposition` and of
:func:`disturbance_fits`, next to the time to build the decomposition (which includes one
validation).

    python experiments/validate_benchmark.py --sides 50,100,150 --divisions 6,10,12 --repeats 3
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from tubejax.model.geometry import Ball
from tubejax.model.workspace import box_grid, parse_grid_map
from tubejax.model.workspace.validate import disturbance_fits, validate_decomposition


def rooms_map(side: int, seed: int) -> str:
    """A ``side`` x ``side`` grid map: walls every 10 squares with doors, 5 % random obstacles."""
    rng = np.random.default_rng(seed)
    g = np.full((side, side), ".")
    g[::10, :] = "#"
    g[:, ::10] = "#"
    g[5::10, :] = "."
    g[:, 5::10] = "."
    g[rng.random((side, side)) < 0.05] = "#"
    g[1, 1] = "1"
    return "\n".join("".join(r) for r in g)


def best(f, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        f()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sides", default="50,100,120", help="grid map sides (comma-separated)")
    ap.add_argument("--divisions", default="6,10,12", help="4-D box grid divisions per axis (comma-separated)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    print(f"{'workspace':<22}{'cells':>8}{'build s':>10}{'validate s':>12}{'fits s':>9}")
    W = Ball(2, 0.3)
    for side in map(int, args.sides.split(",")):
        text = rooms_map(side, args.seed)
        t = time.perf_counter()
        d = parse_grid_map(text, f"rooms {side}x{side}")
        build = time.perf_counter() - t
        v = best(lambda: validate_decomposition(d), args.repeats)
        f = best(lambda: disturbance_fits(d, W), args.repeats)
        print(f"{d.name:<22}{d.n_cells:>8}{build:>10.3f}{v:>12.3f}{f:>9.3f}")
    W4 = Ball(4, 0.01)
    for k in map(int, args.divisions.split(",")):
        t = time.perf_counter()
        d = box_grid([0] * 4, [1] * 4, k, obstacles=[([0.3] * 4, [0.6] * 4)], name=f"box grid {k}^4")
        build = time.perf_counter() - t
        v = best(lambda: validate_decomposition(d), args.repeats)
        f = best(lambda: disturbance_fits(d, W4), args.repeats)
        print(f"{d.name:<22}{d.n_cells:>8}{build:>10.3f}{v:>12.3f}{f:>9.3f}")


if __name__ == "__main__":
    main()
