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
# corridor map (on a 3x3 map with `TUBEJAX_NB_SMALL=1`, as in the tests). Everything it shows
# comes from the sweep's own records: the jobs' `metrics.json`, their `.hydra/` configs and the
# sweep plan `sweep.json`, so a sweep over the paper map (or two maps) is analysed on its own
# map(s). It holds no solver logic.
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
import yaml

import tubejax
from tubejax.files import user_path
from tubejax.analyses.sweep_results import (add_conservatism, collect_metrics, group_keys, problem_jobs, short_names,
                                            sweep_jobs)
from tubejax.analyses.plot import sweeps

ROOT = Path(tubejax.__file__).resolve().parents[1]      # the checkout (conf/, experiments/), wherever the kernel runs
SMALL = os.environ.get("TUBEJAX_NB_SMALL", "0") == "1"


def run_app(cmd, cwd=ROOT):
    """Run an experiments app; its own error line if it fails."""
    p = subprocess.run(cmd, capture_output=True, text=True, cwd=cwd)
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd[1:3]))} failed (exit {p.returncode}):\n{p.stderr[-3000:]}")
    return p


sweep_dir = os.environ.get("TUBEJAX_SWEEP_DIR")
if sweep_dir:                               # a relative path: from where the command was typed, or the repository root
    sweep_dir = user_path(sweep_dir, "TUBEJAX_SWEEP_DIR", [ROOT])
else:
    sweep_dir = Path(tempfile.mkdtemp(prefix="tubejax-sweep-"))
    radii = "0,0.15,0.3" if SMALL else "0,0.05,0.1,0.15,0.2,0.25,0.3"
    lmax = "4,7" if SMALL else "4,7,10"
    run_app([sys.executable, str(ROOT / "experiments" / "abstract.py"), "-m", "progress=false",
             "workspace=" + ("tiny" if SMALL else "corridor"), "solver=" + ("highs" if SMALL else "pdhg"),
             f"disturbance.radius={radii}", "method=tube,openloop,exact2d", "zshape=box,diamond", f"L_max={lmax}",
             f"hydra.sweep.dir={sweep_dir}"])
sweep_dir = Path(sweep_dir)
jobs = sweep_jobs(sweep_dir)
df = add_conservatism(collect_metrics(sweep_dir))
keys = group_keys(df)                      # every setting that differs between jobs: kept apart below
names = short_names(df["workspace"])
print(f"{len(df)} jobs; settings that vary: {', '.join(keys)}; workspaces: {', '.join(names.values())}")
problem_jobs(jobs)                         # failed, unfinished or never run: empty for a complete sweep

# %%
cols = [k for k in keys if k not in ("method", "zshape", "radius", "L_max")]
df[cols + ["method", "zshape", "radius", "L_max", "n_edges", "exact_edges", "conservatism", "solve_seconds"]]

# %% [markdown]
# ## Transitions against disturbance size, and conservatism against the exact reference
# `exact2d` is the most any feedback could achieve; the tube method's ratio stays near 1 while
# open-loop reachability collapses as `r` grows (the disturbance accumulates along the horizon).

# %%
drawable = sweeps.available_plots(df)


def draw_panels(names):
    """The plots ``names`` that have data, side by side; the others named with what they need."""
    shown = [n for n in names if drawable[n] is None]
    for n in names:
        if drawable[n] is not None:
            print(f"{n}: not drawn ({drawable[n]})")
    if shown:
        fig, axes = plt.subplots(1, len(shown), figsize=(7 * len(shown), 4.5), squeeze=False)
        for ax, name in zip(axes.flat, shown):
            sweeps.PLOTS[name](df, ax=ax)
        fig.tight_layout()


draw_panels(("edges_vs_radius", "conservatism"))

# %% [markdown]
# ## Effect of `L_max` and of the Z shape; runtime
# One line per method and Z shape, radius and any other swept setting; the runtime is the solve
# time without JIT compiling (`solve_seconds`).

# %%
draw_panels(("lmax", "runtime"))

# %%
rows = [k for k in keys if k not in ("method", "zshape", "L_max")] or ["radius"]
table = df.assign(workspace=df["workspace"].map(names))
table.pivot_table(index=rows, columns=["method", "zshape", "L_max"], values="n_edges")

# %% [markdown]
# ## Every radius from one solve
#
# `experiments/radius.py` solves `rho*(i, j, L)` (the largest disturbance at which the tube, or
# the open-loop plan, exists) for every candidate pair and horizon once. A pair is a transition
# at radius `rho` iff its critical disturbance `max_L rho*(i, j, L) >= rho`, so `n_edges(rho)` is
# an exact step function (HiGHS makes every pair's critical value exact), and the systems at the
# requested `radii` are written, verified, to `r<radius>/`. It runs here with a tube job's own
# overrides (its `.hydra/overrides.yaml`: the same map, system, disturbance shape and Z), once
# per problem of the sweep (per value of the settings other than radius, `L_max`, method and
# Z) and per kind of Z swept (the open loop, which has no Z, once); every Z's curve goes on the
# problem's plot in its own colour, and the sweep's jobs of that problem must lie on the curves,
# at every `L_max`. `exact2d` is
# only known at the sampled radii. Set `TUBEJAX_RADIUS_DIR` to a run of the app to use it
# instead (it is compared with the sweep's jobs of its own map and system only):
#
# ```bash
# python experiments/radius.py radii=[0,0.1,0.2,0.3] hydra.run.dir=outputs/radius-paper
# TUBEJAX_RADIUS_DIR=outputs/radius-paper jupyter lab notebooks/sweep_analysis.py
# ```

# %%
from tubejax.analyses.plot import radius_curves

FIXED_Z = ("box", "diamond", "cell", "regular")          # the kinds experiments/radius.py takes
problem_keys = [k for k in keys if k not in ("radius", "L_max", "method", "zshape", "solver")]


def job_overrides(job_dir):
    """The job's own command-line overrides and the directory it was launched from."""
    hydra_dir = Path(job_dir) / ".hydra"
    overrides = yaml.safe_load((hydra_dir / "overrides.yaml").read_text()) or []
    cwd = Path(yaml.safe_load((hydra_dir / "hydra.yaml").read_text())["hydra"]["runtime"]["cwd"])
    drop = ("L_max", "progress", "resume", "overwrite", "radii", "figures")
    return [o for o in overrides if o.split("=", 1)[0].lstrip("+~") not in drop], (cwd if cwd.is_dir() else ROOT)


def same_problem(doc, rows):
    """The sweep rows of the radius run's own problem (its map and system, from its inputs record)."""
    rec = doc["inputs"] or {}
    ws = ((rec.get("workspace") or {}).get("map_file") or {}).get("resolved")
    out = rows[rows["system"] == (rec.get("system") or {}).get("name")]
    out = out[(out["method"] != "tube") | (out["zshape"] == radius_curves.doc_zshape(doc))]   # its own Z
    return out[out["workspace"] == ws] if ws else out.iloc[0:0]


radius_dir = os.environ.get("TUBEJAX_RADIUS_DIR")
radius_dir = user_path(radius_dir, "TUBEJAX_RADIUS_DIR", [ROOT]) if radius_dir else None
tube = df[(df["method"] == "tube") & df["zshape"].isin(FIXED_Z)]
problems = [g for _, g in tube.groupby(problem_keys, dropna=False)] if problem_keys else [tube]
runs = []                        # (problem label, radius.json document, the sweep rows of that problem and Z)
for k, g in enumerate(problems[:1] if radius_dir else problems):
    if radius_dir:
        doc = radius_curves.load_radius_document(radius_dir)
        runs.append(("TUBEJAX_RADIUS_DIR", doc, same_problem(doc, df)))
        break
    top = int(g["L_max"].max())
    label = None
    for n_z, z in enumerate(sorted(g["zshape"].unique(), key=lambda z: (z != "box", z))):   # every Z of the sweep
        job = g[(g["zshape"] == z) & (g["L_max"] == top)].sort_values("radius").iloc[-1]   # W0: its largest W
        rows = df
        for key in problem_keys:
            rows = rows[rows[key] == job[key]]
        rows = rows[(rows["method"] != "tube") | (rows["zshape"] == z)]
        overrides, cwd = job_overrides(job["job_dir"])
        out = Path(tempfile.mkdtemp(prefix="tubejax-radius-"))
        radii = "[" + ",".join(f"{r:g}" for r in sorted(rows["radius"].unique())) + "]"
        only_tube = ["radius_methods=[tube]"] if n_z else []        # open loop does not depend on Z: once
        run_app([sys.executable, str(ROOT / "experiments" / "radius.py"), *overrides, "progress=false",
                 "figures=false", f"L_max={top}", f"radii={radii}", *only_tube, f"hydra.run.dir={out}"], cwd=cwd)
        doc = radius_curves.load_radius_document(out)
        label = ", ".join(f"{key}={names.get(job[key], job[key])}" for key in problem_keys) or names[job["workspace"]]
        runs.append((label, doc, rows))
for label in dict.fromkeys(lab for lab, _, _ in runs):          # one figure per problem, every Z on it
    mine = [(doc, same) for lab, doc, same in runs if lab == label]
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2))
    for n_z, (doc, same) in enumerate(mine):
        radius_curves.plot_n_edges_curves(doc, sweep=same, ax=axes[0], exact=n_z == 0,
                                          forms=None if n_z == 0 else ["tube"])
        radius_curves.plot_rho_star_histogram(doc, ax=axes[1])
    axes[0].set_title(f"n_edges(rho), L_max = {mine[0][0]['L_max']}")
    axes[0].legend(fontsize=7)
    fig.suptitle(label)
    fig.tight_layout()

# %% [markdown]
# The sweep's jobs of each problem lie on its curves at every `L_max` (checked below: `n_edges`
# against `L_max` comes from the same solve), and the systems written at the requested radii were
# verified against their sources.

# %%
check = []
for label, doc, same in runs:
    for form, f in doc["forms"].items():
        vs = f["n_edges_vs_L_max"]
        for _, job in same[same["method"] == form].iterrows():
            if job["radius"] in vs["radii"] and job["L_max"] in vs["L_max"]:
                curve = vs["n_edges"][vs["radii"].index(job["radius"])][vs["L_max"].index(job["L_max"])]
                check.append({"problem": label, "method": form, "radius": job["radius"], "L_max": job["L_max"],
                              "sweep job": job["n_edges"], "one solve": curve})
check = pd.DataFrame(check, columns=["problem", "method", "radius", "L_max", "sweep job", "one solve"])
if not len(check):
    print("no sweep job shares the radius run's problem (map, system): nothing to compare")
assert (check["sweep job"] == check["one solve"]).all(), check[check["sweep job"] != check["one solve"]]
for label, doc, _ in runs:
    fig, ax = plt.subplots(figsize=(6, 4))
    radius_curves.plot_n_edges_vs_L_max(doc, "tube", ax=ax)
    ax.set_title(f"{ax.get_title()} ({label})")
    fig.tight_layout()
check
