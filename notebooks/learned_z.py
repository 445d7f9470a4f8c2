# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Learned cross-sections Z against the fixed shapes
#
# For each case (a workspace, a system) we build the verified abstraction with the fixed
# cross-sections (box, cell, diamond, regular, where they fit the cells, and chamfer: the cell's shape
# with its corners cut, twice the cell's vertices, paired with the cell's vertices and edge midpoints),
# with `learned` (one Z per
# cell shape, learned with optax) and `learned_pair` (one Z per ordered pair, learned from the shared
# one), exactly as `experiments/abstract.py zshape=...` does: `learn_table` writes the table the run
# saves as `learned_z.json`, `assignment_from_table` turns it into the run's cross-sections, and
# every edge goes through the normal `build_abstraction` path (HiGHS verdicts, float64 re-check,
# exact proofs). exact2d (the most any feedback achieves) is the reference in 2-D.
#
# `TUBEJAX_NB_SMALL=1` (the tests) runs one small case; the full run takes tens of minutes on two
# cores. The Hydra sweep of the README writes the same comparison as `metrics.json` files: set
# `TUBEJAX_ZSWEEP` to its sweep directory to read them at the end.

# %%
import os
import time
from pathlib import Path

import jax
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
import yaml

import tubejax
from tubejax.files import user_path
from tubejax.abstraction import build_abstraction
from tubejax.reachability.exact2d import exact2d_solve_batch
from tubejax.inputs import ProblemInputs
from tubejax.inputs.settings import LEARNED_DEFAULTS
from tubejax.model.zshape.kinds import make_z
from tubejax.analyses.zshape import LearnOptions
from tubejax.analyses.zshape.learn_run import learn_table
from tubejax.model.zshape.z_table import assignment_from_table

jax.config.update("jax_enable_x64", True)         # the learner solves its LPs in float64
ROOT = Path(tubejax.__file__).resolve().parents[1]      # the checkout (conf/, experiments/), wherever the kernel runs
SMALL = os.environ.get("TUBEJAX_NB_SMALL", "0") == "1"
# (case, workspace, system, init, L_max); init "best": per cell shape the fixed kind that fits and
# certifies most candidate pairs (the app's default, conf/zshape/learned.yaml)
CASES = [("corridor, l1", "corridor", "integrator2d_l1", "best", 10)] if SMALL else [
    ("corridor, l1", "corridor", "integrator2d_l1", "best", 10),
    ("paper, l1", "paper", "integrator2d_l1", "best", 10),
    ("rooms", "rooms", "integrator2d", "best", 10),
    ("paper, custom A", "paper", "custom", "best", 10),
    ("4-D double integrator", "boxgrid4d", "double_integrator", "best", 8),
]
D = LEARNED_DEFAULTS                              # the app's defaults
OPTIONS = LearnOptions(steps=2 if SMALL else D["steps"], learning_rate=D["learning_rate"], horizon=D["horizon"],
                       patience=D["patience"], seed=D["seed"])
FIXED = ["box", "cell", "diamond", "regular", "chamfer"]


def conf(group, name):
    return yaml.safe_load((ROOT / "conf" / group / f"{name}.yaml").read_text())


rows, shapes = [], {}
for case, ws, sysname, init, L_max in CASES:
    inputs = ProblemInputs.from_dict({"workspace": conf("workspace", ws), "system": conf("system", sysname),
                                      "disturbance": conf("disturbance", "ball")}, search_dirs=[ROOT])
    decomp, system = inputs.build_decomposition(), inputs.build_system()
    exact = None
    if decomp.dim == 2:
        ex = build_abstraction(decomp, system, L_max=L_max, method="exact2d", solve_batch=exact2d_solve_batch,
                               progress=False)
        exact = {(e.src, e.dst) for e in ex.edges}
    runs = {}
    for kind in FIXED:
        try:
            Z = tuple(make_z(kind, c) for c in decomp.cells)
        except ValueError:                       # the shape does not fit these cells
            continue
        runs[kind] = (Z, 0.0)
    for mode in ("learned", "learned_pair"):
        t0 = time.perf_counter()
        table = learn_table(decomp, system, mode, init=init, options=OPTIONS._replace(L_max=L_max), progress=False)
        runs[mode] = (assignment_from_table(decomp, table, init), time.perf_counter() - t0)
        if mode == "learned":                     # the first learned shape and the fixed kind it started from
            c0 = np.array(table.to_json()["shapes"][0]["cell"])
            cell = next(c for c in decomp.cells if c.vertices.shape == c0.shape
                        and np.allclose(c.vertices - c.vertices.mean(axis=0), c0))
            nz = table.z_for_cell(cell).n_vertices            # the run (vertex count) this shape kept
            run = next(f for f in table.learning["families"] if f["n_vertices"] == nz)
            shapes[case] = (cell, table, run["start_of_shape"][0])
    for kind, (Z, learn_s) in runs.items():
        ts = build_abstraction(decomp, system, z=Z, zshape=kind, L_max=L_max, progress=False)
        assert np.all(ts.verify() <= 1e-9)
        edges = {(e.src, e.dst) for e in ts.edges}
        rows.append({"case": case, "zshape": kind, "edges": ts.n_edges,
                     "exact proofs": ts.stats["proof"]["exact"],
                     "exact2d edges": None if exact is None else len(exact),
                     "fraction of exact2d": None if exact is None else len(edges) / max(len(exact), 1),
                     "outside exact2d": None if exact is None else len(edges - exact),
                     "learn s": round(learn_s, 1), "abstraction s": round(ts.stats["seconds"], 1)})
df = pd.DataFrame(rows)
df

# %% [markdown]
# ## Transitions per cross-section
# The learned rows can only gain: the learner keeps a Z only where it certifies at least as many pairs
# as its start. No learned edge lies outside exact2d (last column of the table above).

# %%
pivot = df.pivot_table(index="case", columns="zshape", values="edges", sort=False)
gain = pivot[["learned", "learned_pair"]].max(axis=1) - pivot[[k for k in FIXED if k in pivot]].max(axis=1)
ax = pivot.plot.bar(figsize=(max(6, 2.5 * len(pivot)), 3.6), rot=0)
ax.set_ylabel("verified transitions")
ax.figure.tight_layout()
pd.DataFrame({"best fixed": pivot[[k for k in FIXED if k in pivot]].max(axis=1), "gain of learning": gain})

# %% [markdown]
# ## The shapes: learned Z against its start (2-D cases; vertex k pairs with the cell's vertex k, or
# with its k-th point of vertices and edge midpoints for a Z with twice the cell's vertices)

# %%
two_d = [(case, v) for case, v in shapes.items() if v[0].dim == 2]
fig, axes = plt.subplots(1, max(len(two_d), 1), figsize=(3.4 * max(len(two_d), 1), 3.4), squeeze=False)
for ax, (case, (cell, table, start)) in zip(axes[0], two_d):
    for P, style, name in ((make_z(start, cell), "k--", f"start: {start}"), (table.z_for_cell(cell), "C1-", "learned")):
        V = np.vstack([P.vertices, P.vertices[:1]]) / np.sqrt(np.mean(np.sum(P.vertices ** 2, axis=1)))
        ax.plot(V[:, 0], V[:, 1], style, label=name)
    ax.plot(0, 0, "k+")
    ax.set_aspect("equal")
    ax.set_title(case)
    ax.legend(fontsize=8)
fig.tight_layout()

# %% [markdown]
# ## The Hydra sweep (optional)
# `python experiments/abstract.py -m zshape=box,cell,diamond,regular,learned system=integrator2d_l1
# workspace=corridor hydra.sweep.dir=out/zsweep`, then `TUBEJAX_ZSWEEP=out/zsweep`.

# %%
sweep = os.environ.get("TUBEJAX_ZSWEEP")
if sweep:
    sweep = user_path(sweep, "TUBEJAX_ZSWEEP", [ROOT])      # relative: from where the command was typed, or the repository root
    from tubejax.analyses.sweep_results import collect_metrics, group_keys, problem_jobs, short_names, sweep_jobs

    missing = problem_jobs(sweep_jobs(sweep))          # jobs of the sweep without a result, named
    if len(missing):
        display(missing)  # noqa: F821 (IPython)
    m = collect_metrics(sweep)                          # every job of the sweep, on its own map and system
    m["workspace"] = m["workspace"].map(short_names(m["workspace"]))
    keys = [k for k in group_keys(m) if k != "zshape"]
    display(m[keys + ["zshape", "n_edges", "solve_seconds", "learn_seconds"]]  # noqa: F821 (IPython)
            .sort_values(keys + ["n_edges"], ascending=[True] * len(keys) + [False]))
