"""Why no 4-vertex Z closes the 1-norm corridor's gap: the best margins any Z reaches on the pairs
exact2d certifies and the box Z does not.

For each such pair (corridor map, ``integrator2d_l1``, r = 0.2, at exact2d's horizon ``L``), the
margin ``t*`` of: the box Z; the best of ``--samples`` random convex quadrilaterals (seeded,
canonical order, 0 interior); one Z learned for that pair alone (:func:`tubejax.analyses.zshape.learn_z`,
``learned_pair``, from the box); configuration-constrained tubes with the box's 4 normals (every
step a free rectangle) and with an octagon's 8 normals. ``t* >= 0`` certifies. Margins of different
classes are on differently normalised rows: compare signs, not sizes.

Usage::

    python scripts/learned_z_limit.py --samples 500
"""

from __future__ import annotations

import argparse

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

from tubejax.abstraction import build_abstraction  # noqa: E402
from tubejax.reachability.exact2d import exact_edges  # noqa: E402
from tubejax.model.geometry import Ball, Polytope, canonical_vertex_order  # noqa: E402
from tubejax.model.problem import pair_problem  # noqa: E402
from tubejax.model.system import LinearSystem, one_norm_input_set  # noqa: E402
from tubejax.model.workspace.gridmap import load_grid_map  # noqa: E402
from tubejax.analyses.zshape import LearnOptions, learn_z  # noqa: E402
from tubejax.analyses.zshape.ccp import box_normals, ccp_margin, octagon_normals  # noqa: E402
from tubejax.analyses.zshape.margin import PairMargins  # noqa: E402
from tubejax.model.zshape.params import ZFamily, z_from_theta, z_valid  # noqa: E402


def random_quads(rng, n):
    """``n`` random valid quadrilaterals (normalised vertices, canonical order), ``(n, 4, 2)``."""
    fam = ZFamily("polygon", 2, 4, 4)
    out = []
    while len(out) < n:
        ang = np.sort(rng.uniform(0, 2 * np.pi, 4))
        V = canonical_vertex_order(np.c_[np.cos(ang), np.sin(ang)] * rng.uniform(0.3, 1.5, (4, 1)))
        z = np.asarray(z_from_theta(fam, V))
        if bool(z_valid(fam, z)):
            out.append(z)
    return np.stack(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--samples", type=int, default=500)
    ap.add_argument("--pairs", type=int, default=6, help="how many of the missing pairs")
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    decomp = load_grid_map("conf/workspace/maps/corridor.txt")
    system = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=one_norm_input_set(1.0, 2), W=Ball(2, 0.2))
    exact = exact_edges(decomp, system, 10)
    box = {(e.src, e.dst) for e in build_abstraction(decomp, system, zshape="box", progress=False).edges}
    missing = sorted(k for k in exact if k not in box)[:a.pairs]
    fam = ZFamily("polygon", 2, 4, 4)
    quads = random_quads(np.random.default_rng(a.seed), a.samples)
    box_z = Polytope.box([-1.0, -1.0], [1.0, 1.0])
    print(f"{len(exact)} exact2d edges, {len(box)} box-Z edges; {len(missing)} of the "
          f"{len(exact) - len(box)} missing pairs:")
    print("| pair | L | box Z | best of random Z | learned Z (this pair) | CCP 4 normals | CCP 8 normals |")
    print("|---|---|---|---|---|---|---|")
    for (i, j) in missing:
        L = exact[(i, j)][0]
        pm = PairMargins(decomp, system, np.array([(i, j)]), fam, L)
        t_rand = max(float(pm.solve(q[None], np.array([L])).t[0]) for q in quads)
        res = learn_z(decomp, system, mode="learned_pair", init="box", pairs=[(i, j)],
                      options=LearnOptions(steps=40, learning_rate=0.05, horizon="last", L_max=L), progress=False)
        prob = pair_problem(decomp, system, box_z, i, j, L)
        t_box = float(pm.solve(np.asarray(box_z.vertices)[None], np.array([L])).t[0])
        c4 = ccp_margin(prob, box_normals())[0]
        c8 = ccp_margin(prob, octagon_normals())[0]
        print(f"| ({i}, {j}) | {L} | {t_box:+.4f} | {t_rand:+.4f} | {float(res.margins[0]):+.4f} | "
              f"{c4:+.4f} | {c8:+.4f} |", flush=True)


if __name__ == "__main__":
    main()
