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
# # Sweep analysis: tube vs open-loop vs exact reachability
#
# How much less conservative is the tube method than open-loop reachability, and how do the
# disturbance size, the shape of `Z` and `L_max` change the abstraction? The last part draws
# the exact curves `n_edges(rho)` from ONE solve (`experiments/radius.py`) with the sweep's
# points on top, and how far each transition is from breaking.
#
# This notebook loads a multirun directory written by `experiments/abstract.py -m` (set
# `TUBEJAX_SWEEP_DIR`), or, if none is given, runs a small sweep itself on the validation
# corridor map (on a 3x3 map with `TUBEJAX_NB_SMALL=1`, as in the tests). It holds no solver logic: it reads `metrics.json` files and plots them.
#
# A full sweep on the paper map, in parallel on this machine:
#
# ```bash
# python experiments/abstract.py -m hydra/launcher=parallel \
#     disturbance.radius=0,0.05,0.1,0.15,0.2,0.25,0.3 method=tube,openloop,exact2d \
#     zshape=box,diamond L_max=5,10 hydra.sweep.dir=multirun/paper
# TUBEJAX_SWEEP_DIR=multirun/paper jupyter lab notebooks/sweep_analysis.py
# ```

# %%
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import pandas as pd

from tubejax.analysis import add_conservatism, collect_metrics
from tubejax.plot import sweeps

ROOT = Path.cwd() if (Path.cwd() / "experiments").exists() else Path.cwd().parent
SMALL = os.environ.get("TUBEJAX_NB_SMALL", "0") == "1"
sweep_dir = os.environ.get("TUBEJAX_SWEEP_DIR")
if not sweep_dir:
    sweep_dir = Path(tempfile.mkdtemp(prefix="tubejax-sweep-"))
    radii = "0,0.15,0.3" if SMALL else "0,0.05,0.1,0.15,0.2,0.25,0.3"
    lmax = "4,7" if SMALL else "4,7,10"
    cmd = [sys.executable, str(ROOT / "experiments" / "abstract.py"), "-m", "progress=false",
           "workspace=" + ("tiny" if SMALL else "corridor"), "solver=" + ("highs" if SMALL else "pdhg"), f"disturbance.radius={radii}", "method=tube,openloop,exact2d",
           "zshape=box,diamond", f"L_max={lmax}", f"hydra.sweep.dir={sweep_dir}"]
    subprocess.run(cmd, check=True, capture_output=True, cwd=ROOT)
df = add_conservatism(collect_metrics(sweep_dir))
df[["method", "zshape", "radius", "L_max", "n_edges", "exact_edges", "conservatism", "seconds"]]

# %% [markdown]
# ## Transitions against disturbance size, and conservatism against the exact reference
# `exact2d` is the most any feedback could achieve; the tube method's ratio stays near 1 while
# open-loop reachability collapses as `r` grows (the disturbance accumulates along the horizon).

# %%
fig, axes = plt.subplots(1, 2, figsize=(11, 4))
sweeps.plot_edges_vs_radius(df, ax=axes[0])
sweeps.plot_conservatism(df, ax=axes[1])
fig.tight_layout()

# %% [markdown]
# ## Effect of `L_max` and of the Z shape; runtime

# %%
fig, axes = plt.subplots(1, 2, figsize=(11, 4))
sweeps.plot_lmax(df[df["zshape"] == "box"], ax=axes[0])
sweeps.plot_runtime(df, ax=axes[1])
fig.tight_layout()

# %%
pivot = df[df["L_max"] == df["L_max"].max()].pivot_table(index="radius", columns=["method", "zshape"],
                                                         values="n_edges")
pivot

# %% [markdown]
# ## Every radius from one solve
#
# `experiments/radius.py` solves `rho*(i, j, L)` (the largest disturbance at which the tube, or
# the open-loop plan, exists) for every candidate pair and horizon once. A pair is a transition
# at radius `rho` iff its critical disturbance `max_L rho*(i, j, L) >= rho`, so `n_edges(rho)` is
# an exact step function (HiGHS makes every pair's critical value exact), and the systems at the
# requested `radii` are written, verified, to `r<radius>/`. The sweep's jobs must lie on the
# curves (same workspace, `Z = box`, the largest `L_max`); `exact2d` is only known at the
# sampled radii. Set `TUBEJAX_RADIUS_DIR` to a run of the app to use it instead:
#
# ```bash
# python experiments/radius.py radii=[0,0.1,0.2,0.3] hydra.run.dir=outputs/radius-paper
# TUBEJAX_RADIUS_DIR=outputs/radius-paper jupyter lab notebooks/sweep_analysis.py
# ```

# %%
from tubejax.plot import radius_curves

radius_dir = os.environ.get("TUBEJAX_RADIUS_DIR")
if not radius_dir:
    radius_dir = Path(tempfile.mkdtemp(prefix="tubejax-radius-"))
    top = int(df["L_max"].max())
    cmd = [sys.executable, str(ROOT / "experiments" / "radius.py"), "progress=false",
           "workspace=" + ("tiny" if SMALL else "corridor"), "solver=" + ("highs" if SMALL else "pdhg"),
           f"L_max={top}", "radii=[" + ",".join(f"{r:g}" for r in sorted(df["radius"].unique())) + "]",
           f"hydra.run.dir={radius_dir}"]
    subprocess.run(cmd, check=True, capture_output=True, cwd=ROOT)
doc = radius_curves.load_radius_document(radius_dir)
map_file = doc["inputs"]["workspace"].get("map_file") or {}
same = df[df["workspace"] == map_file.get("resolved")]          # the sweep's jobs on the same map
same = same if len(same) else df
fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
radius_curves.plot_n_edges_curves(doc, sweep=same, ax=axes[0])
radius_curves.plot_rho_star_histogram(doc, ax=axes[1])
fig.tight_layout()

# %% [markdown]
# The sweep's jobs lie on the curves (checked below), and the systems written at the requested
# radii were verified against their sources; `n_edges` against `L_max` comes from the same run.

# %%
check = []
for form, f in doc["forms"].items():
    jobs = same[(same["method"] == form) & (same["L_max"] == doc["L_max"])
                & ((same["zshape"] == "box") | (form != "tube"))]
    for r, n in zip(jobs["radius"], jobs["n_edges"]):
        k = f["n_edges_vs_L_max"]["radii"].index(r) if r in f["n_edges_vs_L_max"]["radii"] else None
        curve = f["n_edges_vs_L_max"]["n_edges"][k][-1] if k is not None else None
        check.append({"method": form, "radius": r, "sweep job": n, "one solve": curve})
check = pd.DataFrame(check).drop_duplicates()
assert (check["sweep job"] == check["one solve"]).all(), check
fig, ax = plt.subplots(figsize=(6, 4))
radius_curves.plot_n_edges_vs_L_max(doc, "tube", ax=ax)
fig.tight_layout()
check
