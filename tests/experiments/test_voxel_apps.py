"""Scale-out in 3-D: a voxel map's abstraction split into shards by a Hydra multirun (joblib
launcher) merges into the unsharded system, and the batched solver sharded over two host devices
gives the verdicts of one device."""

import json
import os
import subprocess
import sys

from test_resume_app import ROOT, abstract, run, same_files

VOXELS = "1...\n.#..\n....\n---\n....\n.##.\n...2\n"

SHARDED_3D = r'''
import numpy as np, jax
jax.config.update("jax_enable_x64", True)
from tubejax.model.workspace.voxelmap import parse_voxel_map
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.geometry import Ball
from tubejax.model.zshape.kinds import make_z
from tubejax.model.problem import pair_problem
from tubejax.lp.batch.batch_solver import PdhgBatchSolver
assert len(jax.devices()) == 2
dec = parse_voxel_map(%r)
assert dec.cells[0].dim == 3
sysm = LinearSystem(A=np.eye(3), B=0.5 * np.eye(3), U=box_input_set(1.0, 3), W=Ball(3, 0.05))
Z = [make_z("box", c) for c in dec.cells]
probs = [pair_problem(dec, sysm, Z[i], i, j, 3) for i in range(8) for j in range(dec.n_cells) if i != j]
mesh = jax.make_mesh((2,), ("batch",))
sharded = PdhgBatchSolver(pool=32, min_bucket=32, tail_width=None, mesh=mesh)
a = sharded(probs)
b = PdhgBatchSolver(pool=32, min_bucket=32, tail_width=None)(probs)
assert [v.status for v in a] == [v.status for v in b]
assert [v.provenance for v in a] == [v.provenance for v in b]
np.testing.assert_allclose([v.margin for v in a], [v.margin for v in b], rtol=1e-9, atol=1e-12)
(exe,) = sharded._compiled.values()
specs = {str(s.spec) for s in jax.tree_util.tree_leaves(exe.compiled.input_shardings[0])
         if isinstance(s, jax.sharding.NamedSharding)}
assert any("batch" in s for s in specs), specs
print("OK", sum(v.status == "edge" for v in a), len(a))
''' % VOXELS


def test_3d_shards_through_a_joblib_multirun_merge_into_the_unsharded_system(tmp_path):
    voxels = tmp_path / "voxels.txt"
    voxels.write_text(VOXELS)
    full = tmp_path / "full"
    p = abstract(full, "system=integrator3d", "disturbance.radius=0.05", "L_max=4", map_file=voxels)
    assert p.returncode == 0, p.stderr[-3000:]
    sweep = tmp_path / "sweep"
    p = run("abstract.py", "-m", "progress=false", "solver=highs", f"workspace.map_file={voxels}",
            "system=integrator3d", "disturbance.radius=0.05", "L_max=4",
            "hydra/launcher=parallel", "shard.count=2", "shard.index=0,1", f"hydra.sweep.dir={sweep}")
    assert p.returncode == 0, p.stderr[-3000:]
    assert len([d for d in sweep.iterdir() if (d / "transitions.json").exists()]) == 2
    m = run("merge.py", str(sweep))
    assert m.returncode == 0, m.stderr[-3000:]
    same_files(sweep / "merged", full)
    v = subprocess.run([sys.executable, "-m", "tubejax", "verify", str(sweep / "merged"), "--quiet"],
                       cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert v.returncode == 0 and "verify OK" in v.stdout, v.stdout + v.stderr


def test_3d_batch_axis_shards_over_two_host_devices():
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", JAX_PLATFORMS="cpu")
    res = subprocess.run([sys.executable, "-c", SHARDED_3D], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=300)
    assert res.returncode == 0, res.stderr[-3000:]
    assert any(line.startswith("OK ") for line in res.stdout.splitlines()), res.stdout[-3000:]


def test_the_drone_flies_through_the_tiny_building_in_the_simulate_app(tmp_path):
    """+experiment=drone6d_tiny end to end: product abstraction, verify_product, plan, adversarial
    runs in float64 with no violation (exit code 0), fig10_flight3d written."""

    out = tmp_path / "flight"
    p = run("simulate.py", "+experiment=drone6d_tiny", "progress=false", "sim.runs=200", "figures.runs_drawn=5",
            f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads((out / "simulation.json").read_text())
    assert s["runs"] == 200 and s["tube_exits"] == s["obstacle_entries"] == s["workspace_exits"] == 0
    assert s["runs_reaching_all_targets"] == 200 and s["max_input_violation"] <= 1e-9
    stats = json.loads((out / "product.json").read_text())
    assert stats["cells"] == 1008 and stats["n_edges"] > 0 and stats["verify"]["n_edges_checked"] == stats["n_edges"]
    assert (out / "fig10_flight3d.png").is_file() and (out / "fig9_tubes3d.png").is_file()


def test_a_product_run_counts_its_edges_in_metrics_and_sweeps_read_them_from_its_arrays(tmp_path):
    """abstract.py product=true: metrics.json counts the edges without listing them (on the 6-D building the list
    was a 295 MB file); edge_sets reads the run's edges from product_transitions.npz, the same as load_product's."""
    import numpy as np

    from tubejax.abstraction.product_store import load_product
    from tubejax.analyses.sweep_results import edge_sets

    voxels = tmp_path / "voxels.txt"
    voxels.write_text(VOXELS)
    out = tmp_path / "sweep" / "0"
    p = abstract(out, "system=integrator3d", "disturbance.radius=0.05", "L_max=4", "product=true", map_file=voxels)
    assert p.returncode == 0, p.stderr[-3000:]
    m = json.loads((out / "metrics.json").read_text())
    ps = load_product(out)
    assert "edges" not in m and m["product"] is True and m["n_edges"] == ps.n_edges > 0
    got = edge_sets(tmp_path / "sweep")[str(out)]
    assert got == {(int(i), int(j)): int(L) for i, j, L in zip(ps.src, ps.dst, ps.L)}
    assert len(got) == ps.n_edges and np.all(ps.L >= 1)


def test_the_simulate_app_plans_over_a_saved_product_run_and_refuses_one_shard(tmp_path):
    """abstraction_dir holding a product run (product_transitions.json|npz): loaded with its problem rebuilt
    from its sources, verified as a built one is, planned and simulated; one shard of a run is refused."""
    problem = ("system=drone6d", "workspace=building3d_tiny", "zshape=cell", "+workspace.velocity_divisions=[4,3,3]",
               "product=true", "L_max=8", "disturbance.radius=0.01")
    saved = tmp_path / "saved"
    p = run("abstract.py", "progress=false", f"hydra.run.dir={saved}", *problem)
    assert p.returncode == 0, p.stderr[-3000:]
    out = tmp_path / "flight"
    p = run("simulate.py", "+experiment=drone6d_tiny", "progress=false", "sim.runs=100", "figures.enabled=false",
            f"abstraction_dir={saved}", f"hydra.run.dir={out}")
    assert p.returncode == 0, p.stderr[-3000:]
    s = json.loads((out / "simulation.json").read_text())
    assert s["runs"] == 100 and s["tube_exits"] == s["obstacle_entries"] == s["workspace_exits"] == 0
    assert s["runs_reaching_all_targets"] == 100
    stats = json.loads((out / "product.json").read_text())
    assert stats["cells"] == 1008 and stats["verify"]["n_edges_checked"] == stats["n_edges"] > 0
    assert "seconds_load" in stats
    shard = tmp_path / "shard"
    p = run("abstract.py", "progress=false", f"hydra.run.dir={shard}", "shard.count=2", "shard.index=0", *problem)
    assert p.returncode == 0, p.stderr[-3000:]
    p = run("simulate.py", "+experiment=drone6d_tiny", "progress=false", f"abstraction_dir={shard}",
            f"hydra.run.dir={tmp_path / 'refused'}")
    assert p.returncode != 0 and "holds shard 0 of 2" in p.stderr and "Traceback" not in p.stderr
