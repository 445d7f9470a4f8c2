"""The sweep table and plot of the fraction of the limit (experiments/aggregate.py), from hand-written job folders."""

import json
import math

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import yaml  # noqa: E402

from tubejax.analyses.plot.conservatism import plot_fraction_of_limit  # noqa: E402
from tubejax.analyses.sweep_results import collect_fraction_of_limit  # noqa: E402


def _job(root, name, radius, converged, fractions, L_max=10, dirs=None):
    d = root / name
    (d / ".hydra").mkdir(parents=True)
    (d / ".hydra" / "config.yaml").write_text(yaml.safe_dump(
        {"disturbance": {"kind": "ball", "radius": radius}, "zshape": {"kind": "box"}, "L_max": L_max,
         "target": 6, "methods": list(fractions), "progress": False, "abstraction_dirs": dirs}))
    doc = {"limit": {"area": 10.0, "iterations": 5, "converged": converged}, "free_area": 12.0, "target_area": 1.0,
           "methods": {m: {"winning_area": 10.0 * f, "winning_cells": [0], "fraction_of_limit": f if converged else None}
                       for m, f in fractions.items()}}
    (d / "conservatism.json").write_text(json.dumps(doc))


def test_rows_per_job_and_method_and_no_point_without_convergence(tmp_path):
    _job(tmp_path, "a", 0.1, True, {"tube": 0.5, "exact2d": 0.9})
    _job(tmp_path, "b", 0.2, True, {"tube": 0.25, "exact2d": 0.8})
    _job(tmp_path, "c", 0.3, False, {"tube": 0.1, "exact2d": 0.7})
    df = collect_fraction_of_limit(tmp_path)
    assert len(df) == 6 and set(df["series"]) == {"tube (box)", "exact2d"} and set(df["group"]) == {""}
    tube = df[df["series"] == "tube (box)"].sort_values("radius")
    assert tube["radius"].tolist() == [0.1, 0.2, 0.3]
    assert tube["fraction_of_limit"].tolist()[:2] == [0.5, 0.25] and math.isnan(tube["fraction_of_limit"].iloc[2])
    assert tube["converged"].tolist() == [True, True, False]
    ax = plot_fraction_of_limit(df)
    assert {l.get_label() for l in ax.get_lines()} == {"tube (box)", "exact2d", "limit"}
    plt.close(ax.figure)


def test_other_swept_settings_become_groups(tmp_path):
    _job(tmp_path, "a", 0.1, True, {"tube": 0.5}, L_max=5)
    _job(tmp_path, "b", 0.1, True, {"tube": 0.6}, L_max=10)
    df = collect_fraction_of_limit(tmp_path)
    assert sorted(df["group"]) == ["L_max=10", "L_max=5"]
    assert collect_fraction_of_limit(tmp_path / "none").empty


def test_runs_read_from_other_folders_are_not_a_group(tmp_path):
    """Where a job read a method's run (``abstraction_dirs``) is not a setting: one group, one line."""
    _job(tmp_path, "a", 0.1, True, {"tube": 0.5}, dirs={"tube": "out/r1"})
    _job(tmp_path, "b", 0.2, True, {"tube": 0.4})
    df = collect_fraction_of_limit(tmp_path)
    assert set(df["group"]) == {""} and df["radius"].tolist() == [0.1, 0.2]
