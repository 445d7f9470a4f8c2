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
# # Paper reproduction: Section V of Hashimoto, Adachi, Dimarogonas
#
# The point mass `x+ = x + 0.5 u + w`, `|u_i| ≤ 1`, `‖w‖ ≤ 0.2`, `Z = [−1, 1]²`, `L_max = 10`,
# on the 10×10 paper map (67 free cells, regions 1–6), then the plan `1 → 3 → 4 → 5 → 6` and
# closed-loop runs. Set `TUBEJAX_PAPER_DIR` to a directory written by `experiments/paper.py` to
# load its transition system; otherwise the abstraction is built here (about 15 s).

# %%
import json
import os
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

import tubejax
from tubejax.files import user_path
from tubejax.abstraction import build_abstraction
from tubejax.analyses.control import SimulationRuns, plan_sequence, simulate
from tubejax.model.geometry import Ball
from tubejax.analyses.plot import plot_trajectories, plot_transition_graph, plot_tube, plot_workspace
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.transitions.transition_system import TransitionSystem
from tubejax.model.workspace import load_grid_map

ROOT = Path(tubejax.__file__).resolve().parents[1]      # the checkout (conf/, experiments/), wherever the kernel runs
SMALL = os.environ.get("TUBEJAX_NB_SMALL", "0") == "1"
run_dir = os.environ.get("TUBEJAX_PAPER_DIR")
if run_dir:                                 # a relative path: from where the command was typed, or the repository root
    run_dir = user_path(run_dir, "TUBEJAX_PAPER_DIR", [ROOT])
    ts = TransitionSystem.load(run_dir)
else:
    decomp = load_grid_map(ROOT / "conf" / "workspace" / "maps" / "paper.txt")
    system = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    ts = build_abstraction(decomp, system, zshape="box", L_max=10, progress=False)
pd.Series({"states": ts.n_cells, "transitions": ts.n_edges, "paper: states": 67, "paper: transitions": 655,
           "LPs solved": ts.stats["n_lps"], "zero-margin edges": ts.stats["n_zero_margin"],
           "seconds": round(ts.stats["seconds"], 1)})

# %% [markdown]
# The map is the project's substitute for the paper's Fig. 5, which is not published as data: the
# same size and number of free cells, another layout, so the transition counts are not comparable
# (docs/math/paper.md sets them side by side under every reading of the paper's data). The minimal
# horizons say how far a tube can carry a cell: one cell per 3 steps plus one for the shrink
# (docs/math/worked-example.md derives it for the pair 1 -> 2).

# %%
pd.Series([e.L for e in ts.edges]).value_counts().sort_index().rename("edges per minimal L")

# %% [markdown]
# ## Figs. 5 and 6: the workspace and the tube from region 1 to region 2

# %%
idx = ts.edge_index()
c1, c2 = ts.decomposition.cells_with_label("1")[0], ts.decomposition.cells_with_label("2")[0]
fig, axes = plt.subplots(1, 2, figsize=(12, 5.5))
plot_workspace(ts.decomposition, axes[0])
plot_tube(ts, idx[c1, c2], axes[1])
fig.tight_layout()

# %% [markdown]
# ## Fig. 7: the plan 1 → 3 → 4 → 5 → 6 and 50 runs from random states in region 1

# %%
plan = plan_sequence(ts, c1, [3, 4, 5, 6])
res = simulate(ts, plan, SimulationRuns(n_runs=50, mode="uniform", seed=0))
adv = simulate(ts, plan, SimulationRuns(n_runs=500 if SMALL else 10_000, mode="adversarial", seed=1))
fig, axes = plt.subplots(1, 2, figsize=(12, 5.5))
plot_trajectories(ts.decomposition, res, axes[0])
plot_transition_graph(ts, axes[1])
fig.tight_layout()
pd.DataFrame({"50 uniform runs": res.summary(), "adversarial runs": adv.summary()}).loc[
    ["runs", "obstacle_entries", "tube_exits", "runs_reaching_all_targets", "max_tube_violation"]]

# %% [markdown]
# ## Robustness margins
# `t*` is how far every state-space constraint of the tube LP could be tightened and still hold;
# the zero-margin edges are the ones a minimal horizon only just allows.

# %%
m = np.array([e.margin for e in ts.edges])
fig, ax = plt.subplots(figsize=(6, 3))
ax.hist(m, bins=40)
ax.set_xlabel("margin t*")
ax.set_ylabel("edges")
fig.tight_layout()
