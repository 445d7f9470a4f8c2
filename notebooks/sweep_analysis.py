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
# disturbance size, the shape of `Z` and `L_max` change the abstraction?
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
