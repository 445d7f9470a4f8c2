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
# # Tube method vs open-loop baseline on several maps
#
# For each map and disturbance radius we build three abstractions with the library:
# the tube LP (the paper's method), the open-loop baseline (docs/math/open-loop.md) and the exact 2-D
# backward reachability (the best any feedback can do), and compare edge counts and the
# minimal horizons on shared edges. `TUBEJAX_NB_SMALL=1` keeps it small (as in the tests).
#
# Set `TUBEJAX_SWEEP_DIR` to a sweep of `experiments/abstract.py -m` with
# `method=tube,openloop,exact2d` to compare its jobs instead (each on its own map, from the jobs'
# records; at each map's largest `L_max`, tubes with `Z = box`):
#
# ```bash
# python experiments/abstract.py -m workspace=corridor,maze disturbance.radius=0,0.1,0.2 \
#     method=tube,openloop,exact2d hydra.sweep.dir=multirun/baseline
# TUBEJAX_SWEEP_DIR=multirun/baseline jupyter lab notebooks/baseline_comparison.py
# ```

# %%
import os
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

import tubejax
from tubejax.files import user_path
from tubejax.abstraction import METHODS, build_abstraction, method_solver
from tubejax.model.geometry import Ball
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import load_grid_map

ROOT = Path(tubejax.__file__).resolve().parents[1]      # the checkout (conf/, experiments/), wherever the kernel runs
SMALL = os.environ.get("TUBEJAX_NB_SMALL", "0") == "1"
maps = ["tiny", "corridor"] if SMALL else ["corridor", "open", "maze", "paper"]
radii = [0.1, 0.2] if SMALL else [0.0, 0.05, 0.1, 0.15, 0.2, 0.25]
L_max = 4 if SMALL else 10
solvers = {method: method_solver(method) for method in METHODS}       # each method's own reference solver

rows, results = [], {}
sweep_dir = os.environ.get("TUBEJAX_SWEEP_DIR")
if sweep_dir:                                   # the sweep's own jobs, maps and settings
    sweep_dir = user_path(sweep_dir, "TUBEJAX_SWEEP_DIR", [ROOT])   # relative: from where it was typed, or the root
    from tubejax.analyses.sweep_results import collect_metrics, edge_sets, group_keys, short_names

    m = collect_metrics(sweep_dir)
    m = m[m["L_max"] == m.groupby("workspace")["L_max"].transform("max")]
    tube_z = m.loc[m["method"] == "tube", "zshape"]
    m = m[(m["method"] != "tube") | (m["zshape"] == ("box" if (tube_z == "box").any() else tube_z.iloc[0]))]
    for key in group_keys(m):                   # one value of every other swept setting (the first), named
        if key not in ("workspace", "radius", "method", "zshape", "L_max", "solver"):
            print(f"{key}: the sweep has {sorted(m[key].astype(str).unique())}; comparing {m[key].iloc[0]!r}")
            m = m[m[key] == m[key].iloc[0]]
    edges, names = edge_sets(sweep_dir), short_names(m["workspace"])
    maps = list(dict.fromkeys(names[w] for w in m["workspace"]))
    for _, job in m.iterrows():
        results[names[job["workspace"]], job["radius"], job["method"]] = edges[job["job_dir"]]
        rows.append({"map": names[job["workspace"]], "radius": job["radius"], "method": job["method"],
                     "edges": job["n_edges"], "seconds": job["solve_seconds"]})
else:
    for name in maps:
        decomp = load_grid_map(ROOT / "conf" / "workspace" / "maps" / f"{name}.txt")
        for r in radii:
            system = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, r))
            for method, solve in solvers.items():
                ts = build_abstraction(decomp, system, L_max=L_max, solve_batch=solve, method=method, progress=False)
                results[name, r, method] = {(e.src, e.dst): e.L for e in ts.edges}
                rows.append({"map": name, "radius": r, "method": method, "edges": ts.n_edges,
                             "seconds": ts.stats["seconds"]})
df = pd.DataFrame(rows)
methods = [k for k in ("tube", "openloop", "exact2d") if k in set(df["method"])]
assert "exact2d" in methods, "the comparison needs exact2d jobs (add method=exact2d to the sweep)"
df.pivot_table(index=["map", "radius"], columns="method", values="edges")

# %% [markdown]
# ## Edges found, relative to the exact reference

# %%
fig, axes = plt.subplots(1, len(maps), figsize=(4 * len(maps), 3.4), sharey=True)
for ax, name in zip(np.atleast_1d(axes), maps):
    sub = df[df["map"] == name].pivot_table(index="radius", columns="method", values="edges")
    for method in methods[:-1]:
        ax.plot(sub.index, sub[method] / sub["exact2d"].clip(lower=1), marker="o", label=method)
    ax.set_title(name)
    ax.set_xlabel("r")
    ax.set_ylim(-0.05, 1.05)
    ax.grid(alpha=0.3)
np.atleast_1d(axes)[0].set_ylabel("edges / exact edges")
np.atleast_1d(axes)[0].legend()
fig.tight_layout()

# %% [markdown]
# ## Minimal horizons on shared edges
# Soundness check in passing: every method's edges are a subset of the exact ones, and on shared
# edges the exact minimal `L` is never larger.

# %%
check = []
for (name, r, method), edges in results.items():
    if method == "exact2d":
        continue
    exact = results.get((name, r, "exact2d"))
    if exact is None:                           # a sweep without the exact job at this radius
        continue
    shared = set(edges) & set(exact)
    check.append({"map": name, "radius": r, "method": method, "subset_of_exact": set(edges) <= set(exact),
                  "mean_extra_L": float(np.mean([edges[k] - exact[k] for k in shared])) if shared else 0.0})
check = pd.DataFrame(check)
assert check["subset_of_exact"].all()
check
