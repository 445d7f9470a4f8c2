"""Hydra sweeps and their analysis (issue 24, item 3): every job checked before the first starts,
methods that ignore Z run once, jobs added to a sweep directory without touching the others,
``aggregate.py`` keeping every swept setting apart (two maps: two lines, a workspace column)
and naming failed or missing jobs with a non-zero exit."""

import json
import subprocess
import sys
from pathlib import Path

import matplotlib
import pandas as pd
import pytest

matplotlib.use("Agg")

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / "tests" / "data" / "tiny.txt"
CORRIDOR = ROOT / "conf" / "workspace" / "maps" / "corridor.txt"
sys.path.insert(0, str(ROOT / "experiments"))


def app(script, *args, timeout=600):
    return subprocess.run([sys.executable, str(ROOT / "experiments" / script), *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


def sweep(sweep_dir, *overrides, map_file=TINY):
    return app("abstract.py", "-m", "hydra/launcher=basic", "progress=false", "solver=highs",
               f"workspace.map_file={map_file}", "L_max=4", *overrides, f"hydra.sweep.dir={sweep_dir}")


def aggregate(sweep_dir, *args):
    return app("aggregate.py", str(sweep_dir), *args, timeout=300)


def error_line(p) -> str:
    assert "Traceback" not in p.stderr, p.stderr[-3000:]
    lines = [ln for ln in p.stderr.splitlines() if ln.startswith("error: ")]
    assert len(lines) == 1, p.stderr[-3000:]
    return lines[0]


def metrics_files(d: Path) -> list[Path]:
    return sorted(d.rglob("metrics.json"))


def test_sweep_runs_z_ignoring_methods_once_and_aggregates_without_duplicates(tmp_path):
    from tubejax.analyses.sweep_results import collect_metrics
    from tubejax.analyses.plot.sweeps import line_groups

    d = tmp_path / "sweep"
    p = sweep(d, "disturbance.radius=0,0.2", "method=tube,openloop,exact2d", "zshape=box,diamond", "L_max=3,4")
    assert p.returncode == 0, p.stderr[-3000:]
    assert "24 jobs: 16 to run, 8 duplicates skipped" in p.stdout, p.stdout[-2000:]
    assert len(metrics_files(d)) == 16                # tube: 2 Z x 2 r x 2 L_max; openloop, exact2d: 2 r x 2 L_max
    plan = json.loads((d / "sweep.json").read_text())["jobs"]
    dups = [e for e in plan.values() if e["status"] == "duplicate"]
    assert len(dups) == 8 and all(e["reason"].endswith("ignores zshape") for e in dups)
    assert all(not (d / name).exists() for name, e in plan.items() if e["status"] == "duplicate")
    a = aggregate(d)
    assert a.returncode == 0, a.stderr[-3000:]
    df = pd.read_csv(d / "summary.csv")
    assert len(df) == 16 and not df.duplicated(["method", "zshape", "radius", "L_max"]).any()
    assert set(df.loc[df["method"] != "tube", "zshape"]) == {"-"}
    assert set(df.loc[df["method"] == "tube", "zshape"]) == {"box", "diamond"}
    assert (df["solve_seconds"] - (df["seconds"] - df["compile_seconds"])).abs().max() < 1e-9
    ex = df[df["method"] == "exact2d"].set_index(["radius", "L_max"])["n_edges"]
    for _, row in df.iterrows():                      # exact2d bounds every method's edge count
        assert row["n_edges"] <= ex[row["radius"], row["L_max"]]
    for name in ("edges_vs_radius", "conservatism", "lmax", "runtime"):
        assert (d / "plots" / f"{name}.png").stat().st_size > 5000
    jobs = pd.read_csv(d / "jobs.csv")
    assert (jobs["status"] == "finished").sum() == 16 and (jobs["status"] == "skipped").sum() == 8
    # the plots keep every L_max and every Z apart
    t = collect_metrics(d)
    radius_lines = [label for label, _, _ in line_groups(t, "radius")]
    assert len(radius_lines) == 8
    assert sum("L_max=3" in s for s in radius_lines) == sum("L_max=4" in s for s in radius_lines) == 4
    lmax_lines = [label for label, _, _ in line_groups(t, "L_max")]
    assert len(lmax_lines) == 8 and sum(s.startswith("tube (diamond)") for s in lmax_lines) == 2


def test_aggregate_of_a_two_map_sweep_keeps_the_maps_apart(tmp_path):
    import matplotlib.pyplot as plt

    from tubejax.analyses.sweep_results import add_conservatism, collect_metrics
    from tubejax.analyses.plot import sweeps

    d = tmp_path / "sweep"
    p = app("abstract.py", "-m", "hydra/launcher=basic", "progress=false", "solver=highs", "L_max=3",
            f"workspace.map_file={TINY},{CORRIDOR}", "disturbance.radius=0,0.2", "method=tube,exact2d",
            f"hydra.sweep.dir={d}")
    assert p.returncode == 0, p.stderr[-3000:]
    a = aggregate(d)
    assert a.returncode == 0, a.stderr[-3000:]
    df = pd.read_csv(d / "summary.csv")
    assert "workspace" in df and set(df["workspace"]) == {str(TINY), str(CORRIDOR)}
    assert len(df) == 8
    assert "corridor" in a.stdout and "tiny" in a.stdout      # the printed table names the maps
    ax = sweeps.plot_edges_vs_radius(add_conservatism(collect_metrics(d)))
    drawn = [ln for ln in ax.get_lines() if len(ln.get_xdata()) == 2]
    assert len(drawn) == 4                            # tube and exact2d on each map, never one zig-zag line
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert sorted(labels) == ["exact2d · corridor", "exact2d · tiny", "tube (box) · corridor", "tube (box) · tiny"]
    plt.close(ax.figure)
    for _, g in df.groupby(["workspace", "method"]):
        assert sorted(g["radius"]) == [0.0, 0.2]
    assert df.groupby("workspace")["n_cells"].nunique().eq(1).all()


def test_aggregate_names_failed_and_missing_jobs_and_exits_non_zero(tmp_path):
    d = tmp_path / "sweep"
    # without the sweep check (removed on purpose), job 1 fails and stops the sweep: job 2 never runs
    p = sweep(d, "~hydra.callbacks.sweep_check", "disturbance.radius=0.1,-0.1,0.2")
    assert p.returncode != 0 and len(metrics_files(d)) == 1
    a = aggregate(d)
    assert a.returncode == 1, a.stdout + a.stderr
    warn = [ln for ln in a.stderr.splitlines() if ln.startswith("warning:")]
    assert "2 of 3 jobs have no result" in warn[0]
    failed = next(ln for ln in warn if "failed" in ln)
    assert "disturbance.radius=-0.1" in failed and "expected a finite number in [0, 1e6], got -0.1" in failed
    assert any("never ran" in ln and "disturbance.radius=0.2" in ln for ln in warn)
    assert "--allow-missing" in error_line(a)
    assert not (d / "summary.csv").exists()
    a = aggregate(d, "--allow-missing")
    assert a.returncode == 0 and "2 of 3 jobs have no result" in a.stderr
    assert len(pd.read_csv(d / "summary.csv")) == 1
    jobs = pd.read_csv(d / "jobs.csv")
    assert sorted(jobs["status"]) == ["failed", "finished", "missing"]


@pytest.mark.parametrize("script, overrides, message", [
    ("abstract.py", ["disturbance.radius=0.1,0.2,-0.1"],
     "disturbance.radius: expected a finite number in [0, 1e6], got -0.1 (sweep job: disturbance.radius=-0.1)"),
    ("abstract.py", ["method=tube,openloop", "zshape=box,regular,chamfer", "min_margin=0,0.7"],
     "min_margin: expected a finite number in [0, 0.5]"),
    ("radius.py", ["radii=[0.1]", "gap_tol=1e-4,1"], "gap_tol: expected a finite number in [1e-9, 0.01]"),
    ("simulate.py", ["spec.sequence=[1,2]", "sim.runs=5,0"], "sim.runs: expected an integer in [1, 10000000], got 0"),
    ("conservatism.py", ["target=1", "avoid=[2]", "disturbance.radius=0.1,0.2", "sides=8,2"],
     "sides: expected an integer in [3, 4096], got 2"),
    ("conservatism.py", ["target=1,9"], "target: no cell carries the label '9'"),
], ids=["abstract", "abstract-last-of-many", "radius", "simulate", "conservatism", "conservatism-label"])
def test_a_sweep_with_one_bad_value_is_refused_before_any_job_runs(tmp_path, script, overrides, message):
    d = tmp_path / "sweep"
    p = app(script, "-m", "hydra/launcher=basic", "progress=false", "solver=highs", f"workspace.map_file={TINY}",
            "L_max=4", *overrides, f"hydra.sweep.dir={d}")
    assert p.returncode == 2
    line = error_line(p)
    assert message in line and "no job of the sweep was started" in line, line
    assert not list(d.rglob(".hydra")) and not metrics_files(d) if d.exists() else True


def test_a_z_ignoring_job_invalid_only_for_its_zshape_is_a_duplicate(tmp_path):
    # openloop with zshape=chamfer is refused by the input model; with zshape=box it runs once for both
    d = tmp_path / "sweep"
    p = sweep(d, "disturbance.radius=0.1", "method=tube,openloop", "zshape=chamfer,box")
    assert p.returncode == 0, p.stderr[-3000:]
    assert "4 jobs: 3 to run, 1 duplicates skipped" in p.stdout
    df = pd.DataFrame([json.loads(f.read_text()) for f in metrics_files(d)])
    assert sorted(zip(df["method"], df["zshape"])) == [("openloop", "box"), ("tube", "box"), ("tube", "chamfer")]


def test_jobs_are_added_to_an_existing_sweep_dir_without_touching_the_others(tmp_path):
    d = tmp_path / "sweep"
    mp = tmp_path / "map.txt"
    mp.write_text(TINY.read_text())
    args = ["disturbance.radius=0,0.2", "zshape=box,diamond"]
    p = sweep(d, *args, "method=tube,openloop", map_file=mp)
    assert p.returncode == 0, p.stderr[-3000:]
    first = {f: f.stat().st_mtime_ns for f in metrics_files(d)}
    assert len(first) == 6
    a = aggregate(d)
    assert a.returncode == 0 and "conservatism: not drawn (no exact2d jobs" in a.stdout
    assert not (d / "plots" / "conservatism.png").exists()
    # the same command with one more method: only the new jobs run, the finished ones are kept
    p = sweep(d, *args, "method=tube,openloop,exact2d", map_file=mp)
    assert p.returncode == 0, p.stderr[-3000:]
    assert "12 jobs: 2 to run, 4 duplicates skipped" in p.stdout and "6 finished already" in p.stdout, p.stdout
    assert {f: f.stat().st_mtime_ns for f in first} == first
    assert len(metrics_files(d)) == 8
    a = aggregate(d)
    assert a.returncode == 0, a.stderr[-3000:]
    df = pd.read_csv(d / "summary.csv")
    assert len(df) == 8 and sorted(df["method"].value_counts().tolist()) == [2, 2, 4]
    assert (d / "plots" / "conservatism.png").stat().st_size > 5000
    # an unfinished job there is continued with resume=true, never restarted silently
    from sweep_jobs import job_dir_name

    job = d / job_dir_name(["solver=highs", f"workspace.map_file={mp}", "L_max=4", "disturbance.radius=0.2",
                            "zshape=box", "method=tube"])
    assert job.name.startswith("L_max-4+disturbance.radius-0.2+method-tube+") and job / "metrics.json" in first
    man = job / "rounds" / "manifest.json"
    m = json.loads(man.read_text())
    man.write_text(json.dumps({**m, "status": "running"}))
    (job / "metrics.json").unlink()
    (job / "transitions.json").unlink()
    p = sweep(d, *args, "method=tube,openloop,exact2d", map_file=mp)
    assert p.returncode == 2 and "holds an unfinished job; continue it with resume=true" in error_line(p)
    a = aggregate(d)
    assert a.returncode == 1 and "unfinished" in a.stderr and "zshape=box" in a.stderr
    p = sweep(d, *args, "method=tube,openloop,exact2d", "resume=true", map_file=mp)
    assert p.returncode == 0, p.stderr[-3000:]
    assert "1 to run" in p.stdout and "resume=true: continuing the run" in p.stdout + p.stderr
    assert aggregate(d).returncode == 0
    # a finished job made from other inputs (the map file changed) is refused unless overwritten
    mp.write_text(TINY.read_text().replace("2", "3"))
    p = sweep(d, *args, "method=tube,openloop,exact2d", map_file=mp)
    assert p.returncode == 2
    assert "holds a finished job with other inputs (workspace.map_file.sha256" in error_line(p)
    assert {f: f.stat().st_mtime_ns for f in first if f.parent != job} == {f: t for f, t in first.items()
                                                                            if f.parent != job}


def test_job_folder_names_are_safe_distinct_and_usable_as_hydra_run_dir():
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from sweep_jobs import job_dir_name

    a = job_dir_name(["workspace.map_file=/data/my maps/a-b.txt", "L_max=4", "progress=false", "resume=true"])
    assert a == "L_max-4+workspace.map_file-%2Fdata%2Fmy%20maps%2Fa-b.txt"
    names = [job_dir_name([o]) for o in ("x=a/b", "x=a_b", "x=a%2Fb", "x=a,b", "x=[1,2]", "+x=1", "x=1e+3", "x=~1")]
    assert len(set(names)) == len(names)
    assert job_dir_name(["x=1", "y=2"]) != job_dir_name(["x=1+y-2"])
    assert job_dir_name([]) == job_dir_name(["progress=false"]) == "defaults"
    long = job_dir_name(["k=" + "v" * 400])
    assert len(long.encode()) <= 200 and long != job_dir_name(["k=" + "v" * 399 + "w"])
    parser = OverridesParser.create()
    for name in names + [a, long]:                    # given unquoted on the command line, read back unchanged
        assert "/" not in name and not name.startswith(".")
        assert parser.parse_overrides([f"hydra.run.dir=/out/{name}"])[0].value() == f"/out/{name}"


def test_collect_metrics_drops_rows_repeated_over_a_setting_the_method_ignores(tmp_path):
    """A sweep run without the sweep check (or with the basic sweeper) still aggregates once per job."""
    from tubejax.analyses.sweep_results import collect_metrics, group_keys, sweep_jobs

    base = {"solver": "highs", "system": "integrator2d", "workspace": "w.txt", "disturbance": "ball",
            "radius": 0.1, "L_max": 4, "pruning": True, "n_cells": 8, "n_edges": 5, "n_lps": 9, "seconds": 2.0,
            "compile_seconds": 1.5}
    for k, (method, z, mm) in enumerate([("openloop", "box", 0.0), ("openloop", "diamond", 0.0),
                                         ("tube", "box", 0.0), ("tube", "box", 0.1)]):
        job = tmp_path / str(k)
        (job / ".hydra").mkdir(parents=True)
        (job / ".hydra" / "config.yaml").write_text(f"method:\n  name: {method}\nzshape:\n  kind: {z}\n"
                                                   f"min_margin: {mm}\nprogress: {k % 2 == 0}\n")
        (job / ".hydra" / "overrides.yaml").write_text(f"- method={method}\n- zshape={z}\n- min_margin={mm}\n")
        (job / "metrics.json").write_text(json.dumps({**base, "method": method, "zshape": z}))
    df = collect_metrics(tmp_path)
    assert len(df) == 3 and df.attrs["duplicates"] == [str(tmp_path / "1")]
    assert df.attrs["swept"] == ["min_margin"]                 # progress is a flag, zshape a metrics column
    assert group_keys(df) == ["method", "min_margin"]       # zshape: box, or "-" where ignored
    assert list(df["solve_seconds"]) == [0.5, 0.5, 0.5]
    assert set(sweep_jobs(tmp_path)["status"]) == {"finished"}


def test_aggregate_refuses_an_empty_directory(tmp_path):
    a = aggregate(tmp_path)
    assert a.returncode == 2 and "no metrics.json found" in error_line(a)
