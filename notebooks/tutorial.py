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
# # Tutorial: the Python API
#
# `import tubejax as tj` is all this notebook uses: build a transition system, look at it, plan,
# simulate the closed loop, verify, save and export. The system is the paper's point mass
# `x+ = x + 0.5 u + w` with `|u_i| ≤ 1` and `‖w‖ ≤ 0.2`; for every ordered pair of cells and
# horizon `L`, a feasible tube LP certifies that every state of the first cell can be steered into
# the second in `L` steps under every disturbance, without touching an obstacle (a sufficient
# condition: a pair it cannot certify may still be reachable, docs/explanation/limitations.md).
#
# It runs on the project's 10×10 substitute for the paper's map (about a minute, most of it
# compiling the batched solver once), or on a 3×3 map with `L_max = 4` with `TUBEJAX_NB_SMALL=1`
# (as in the tests).

# %%
import json
import os
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import networkx as nx
import pandas as pd

import tubejax as tj

ROOT = Path(tj.__file__).resolve().parents[1]      # the checkout (conf/, experiments/), wherever the kernel runs
SMALL = os.environ.get("TUBEJAX_NB_SMALL", "0") == "1"
print("tubejax", tj.__version__)

# %% [markdown]
# ## 1. A workspace and a system
#
# A grid map has one line per row: `#` an obstacle, `.` a free cell, a digit or letter a free
# cell of that region. `tj.grid_map` takes a file or the map's text (a string with line breaks):
# either way the map is recorded, by path and SHA-256 or as a file saved with the results.

# %%
if SMALL:
    ws = tj.grid_map(ROOT / "conf" / "workspace" / "maps" / "tiny.txt")
    sequence, formula, L_max = [1, 2], "F(l2)", 4
else:
    ws = tj.grid_map("""\
1.2#......
.#.#.##...
.#...#..#.
.###.#.##3
...#...#..
##.#.#.#.#
4..#.#...#
.#.....#..
.#.###.#.5
...6#.....
""", name="paper map")
    sequence, formula, L_max = [1, 3, 4, 5, 6], "F(l3 & F(l5 & F l6)) & G(!l4)", 10
print(ws)
fig, ax = plt.subplots(figsize=(4.5, 4.5))
tj.plot.plot_workspace(ws.decomposition, ax)

# %% [markdown]
# `tj.paper_system(radius)` is the system of the paper's Section V. Any other linear system is a
# `tj.LinearSystem(A=A, B=B, U=U, W=W)`, with `U` a polytope containing 0 (`tj.box_input_set`,
# `tj.one_norm_input_set`, `tj.Polytope.from_vertices`) and `W` a `tj.Ball` or a polytope; the
# same system written out:

# %%
system = tj.paper_system(radius=0.2)
same = tj.LinearSystem(A=[[1.0, 0.0], [0.0, 1.0]], B=[[0.5, 0.0], [0.0, 0.5]], U=tj.box_input_set(1.0, 2), W=tj.Ball(2, 0.2))
system.A, system.B, system.U.vertices, system.W

# %% [markdown]
# ## 2. The abstraction
#
# `tj.abstract` runs the paper's Algorithm 2 with the batched PDHG solver: every pair × horizon of
# a round in one compiled solve, infeasible instances certified by a float64 dual bound, every
# edge confirmed by HiGHS, re-checked in float64 and proved in exact rational arithmetic. The first
# call compiles the solver (later calls with the same settings reuse it).

# %%
ts = tj.abstract(ws, system, L_max=L_max)
pd.Series({"cells": ts.n_cells, "transitions": ts.n_edges, "LPs": ts.stats["n_lps"],
           "exactly proved": ts.stats["proof"]["exact"], "zero-margin edges": ts.stats["n_zero_margin"],
           "seconds": round(ts.stats["seconds"], 1), "of which compiling": round(ts.stats["compile_seconds"], 1)})

# %% [markdown]
# Each edge `i → j` has its minimal horizon `L` (the cost), its robustness margin `t*` (how far every
# constraint could be tightened and the tube still exist), where the verdict came from, and its
# proof level. `ts.to_networkx()` gives the graph.

# %%
edges = pd.DataFrame([{"from": e.src, "to": e.dst, "L": e.L, "margin": e.margin, "provenance": e.provenance,
                       "proof": e.proof} for e in ts.edges])
edges.sort_values("margin", ascending=False).head()

# %%
G = ts.to_networkx()
print(f"{G.number_of_nodes()} nodes, {G.number_of_edges()} edges, strongly connected: {nx.is_strongly_connected(G)}")
fig, axes = plt.subplots(1, 2, figsize=(10, 4.5))
tj.plot.plot_tube(ts, int(edges["margin"].idxmax()), axes[0])
edges["L"].value_counts().sort_index().plot.bar(ax=axes[1], xlabel="minimal horizon L", ylabel="transitions")
fig.tight_layout()

# %% [markdown]
# ### Other methods
#
# The method decides the solver: the open-loop baseline (inputs fixed at time 0, no feedback)
# solves its own LP, and `exact2d` (exact polygon backward reachability, the most any feedback
# can achieve in 2-D) solves none. A solver cannot be paired with another method's problems:

# %%
openloop = tj.abstract(ws, system, L_max=L_max, method="openloop", solver="highs")
exact = tj.abstract(ws, system, L_max=L_max, method="exact2d")
pd.Series({"tube": ts.n_edges, "open loop": openloop.n_edges, "exact 2-D": exact.n_edges}, name="transitions")

# %%
try:
    tj.abstract(ws, system, method="exact2d", solver="pdhg")
except tj.InputError as exc:
    print("refused:", exc)
try:
    tj.abstract(ws, system, L_max=0)
except tj.InputError as exc:
    print("refused:", exc)

# %% [markdown]
# ## 3. Plan and simulate
#
# A sequence of regions starts in the first one and visits the others in order (Dijkstra over the
# transitions, cost `L`). An LTLf formula over the propositions `l<label>` is planned through the
# product with its automaton, refusing every tube that could cross an avoided region (on the
# paper map the formula below is another task: reach 3, then 5, then 6, never entering 4).

# %%
plan = tj.plan(ts, sequence)
by_formula = tj.plan(ts, formula, start=str(sequence[0]))
print(f"sequence {sequence}: cells {plan.plan.cells}, {plan.cost} steps")
print(f"formula {formula!r}: {by_formula.cost} steps")

# %% [markdown]
# `tj.simulate` runs Algorithm 1 along the plan for many runs at once (in float64), with
# disturbances uniform in `W`, on its boundary, or adversarial (pushing toward the nearest facet
# of the next tube set), and checks every state: the report's `ok` says whether every run stayed
# in its tubes, out of the obstacles, and reached every target.

# %%
sim = tj.simulate(ts, plan, runs=200 if SMALL else 2000, disturbance="adversarial", seed=1)
print("ok:", sim.ok, sim.findings)
pd.Series({k: sim.summary[k] for k in ("runs", "steps", "obstacle_entries", "tube_exits", "workspace_exits",
                                       "runs_reaching_all_targets", "runs_satisfying_spec")})

# %%
fig, ax = plt.subplots(figsize=(5, 5))
tj.plot.plot_trajectories(ws.decomposition, sim.result, ax, tj.plot.RunsStyle(max_runs=50))

# %% [markdown]
# ## 4. Verify
#
# `tj.verify` proves a system from its sources, as `python -m tubejax verify` does: it rebuilds the
# problem from the recorded inputs (the map by its SHA-256, the system, `Z`, the settings), checks
# every datum the files copy, re-checks every edge's evidence in float64 and its exact proof, and,
# with `complete=True`, re-solves every pair and horizon that is not an edge with HiGHS.

# %%
report = tj.verify(ts, complete=SMALL)
print("ok:", report.ok, "|", report.n_edges, "edges", report.proof_counts, "|", report.summary)

# %% [markdown]
# ## 5. Save, load, export
#
# `ts.save(DIR)` writes `transitions.json` (the graph, the inputs record, and the provenance:
# tubejax version, git commit, command line) and `transitions.npz` (the tubes); a map given as text
# is saved beside them. The directory then verifies on its own:
# `python -m tubejax verify DIR`.

# %%
out = Path(tempfile.mkdtemp(prefix="tubejax-tutorial-")) if SMALL else ROOT / "outputs" / "tutorial"
ts.save(out)
print(sorted(p.name for p in out.iterdir()))
print(json.loads((out / "transitions.json").read_text())["provenance"])
again = tj.load(out)
print("reloaded:", again.n_edges, "edges; verified from the directory:", tj.verify(out).ok)

# %% [markdown]
# The graph opens in yEd or Gephi (GraphML), in Gephi laid out over the map (GEXF), and in Graphviz
# (`neato -Tpdf transitions.dot -o graph.pdf` keeps the cells where they are):

# %%
for name in ("transitions.graphml", "transitions.gexf", "transitions.dot"):
    ts.export(out / name)
back = nx.read_graphml(out / "transitions.graphml", node_type=int)
print(back.number_of_nodes(), "nodes and", back.number_of_edges(), "edges read back; node 0:", back.nodes[0])
print("".join((out / "transitions.dot").read_text().splitlines(keepends=True)[:6]))
