"""Issue 48, item 2: ``aggregate.py`` validates every job's ``metrics.json`` (schema and ranges) and
never loses a job silently: one it cannot read is named (file and field) and fails the run unless
``--allow-missing``, and ``jobs.csv`` and ``summary.csv`` agree (each job's ``summary_rows``)."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from tubejax.analyses.metrics_row import MetricsRowError, read_metrics_row

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / "tests" / "data" / "tiny.txt"


def _app(script, *args):
    return subprocess.run([sys.executable, str(ROOT / "experiments" / script), *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    d = tmp_path_factory.mktemp("agg") / "sweep"
    p = _app("abstract.py", "-m", "hydra/launcher=basic", "progress=false", "solver=highs", f"workspace.map_file={TINY}",
             "L_max=3", "disturbance.radius=0.05,0.1,0.2", f"hydra.sweep.dir={d}")
    assert p.returncode == 0, p.stderr[-3000:]
    assert len(list(d.rglob("metrics.json"))) == 3
    return d


def _job(d: Path, radius: str) -> Path:
    return next(p.parent for p in d.rglob("metrics.json") if f"radius-{radius}" in p.parent.name)


def _edit(path: Path, **fields) -> None:
    row = json.loads(path.read_text())
    path.write_text(json.dumps({**row, **fields}))


def test_an_honest_sweep_agrees_row_for_row(swept, tmp_path):
    d = shutil.copytree(swept, tmp_path / "s")
    a = _app("aggregate.py", str(d))
    assert a.returncode == 0, a.stderr[-3000:]
    jobs, summary = pd.read_csv(d / "jobs.csv"), pd.read_csv(d / "summary.csv")
    assert list(jobs["status"]) == ["finished"] * 3 and list(jobs["summary_rows"]) == [1, 1, 1]
    assert sorted(summary["job_dir"]) == sorted(jobs["dir"])


def test_a_cut_metrics_file_is_named_and_fails_the_run(swept, tmp_path):
    d = shutil.copytree(swept, tmp_path / "s")
    m = _job(d, "0.1") / "metrics.json"
    text = m.read_text()
    m.write_text(text[: len(text) // 2])
    a = _app("aggregate.py", str(d))
    assert a.returncode == 1 and "Traceback" not in a.stderr, a.stderr[-3000:]
    assert any(ln.startswith("warning:") and "invalid" in ln and str(m) in ln and "not valid JSON" in ln
               for ln in a.stderr.splitlines()), a.stderr
    assert not (d / "summary.csv").exists() and not (d / "jobs.csv").exists()
    a = _app("aggregate.py", str(d), "--allow-missing")
    assert a.returncode == 0, a.stderr[-3000:]
    jobs, summary = pd.read_csv(d / "jobs.csv"), pd.read_csv(d / "summary.csv")
    bad = jobs[jobs["dir"] == str(m.parent)].iloc[0]
    assert bad["status"] == "invalid" and bad["summary_rows"] == 0 and "not valid JSON" in bad["detail"]
    assert len(summary) == 2 and set(summary["job_dir"]) == set(jobs.loc[jobs["status"] == "finished", "dir"])


@pytest.mark.parametrize("fields, expect", [
    ({"n_edges": "many"}, 'n_edges: expected a non-negative integer, got "many"'),
    ({"n_lps": -5}, "n_lps: expected a non-negative integer, got -5"),
    ({"radius": "0.1"}, 'radius: expected a number >= 0 (NaN for a polytope W), got "0.1"'),
    ({"seconds": -1.0}, "seconds: expected a finite number >= 0, got -1.0"),
    ({"n_edges": 3}, "n_edges: is 3, but the row lists"),
])
def test_a_wrong_type_or_range_is_refused_by_name(swept, tmp_path, fields, expect):
    d = shutil.copytree(swept, tmp_path / "s")
    m = _job(d, "0.2") / "metrics.json"
    _edit(m, **fields)
    with pytest.raises(MetricsRowError, match=None) as info:
        read_metrics_row(m)
    assert expect in str(info.value) and str(m) in str(info.value)


def test_a_string_count_and_a_negative_count_fail_the_aggregation_by_name(swept, tmp_path):
    d = shutil.copytree(swept, tmp_path / "s")
    _edit(_job(d, "0.2") / "metrics.json", n_edges="many")
    _edit(_job(d, "0.05") / "metrics.json", n_lps=-5)
    a = _app("aggregate.py", str(d), "--allow-missing")         # plotted from the one valid job, never these
    assert a.returncode == 0 and "Traceback" not in a.stderr, a.stderr[-3000:]
    assert 'n_edges: expected a non-negative integer, got "many"' in a.stderr
    assert "n_lps: expected a non-negative integer, got -5" in a.stderr
    assert len(pd.read_csv(d / "summary.csv")) == 1
    assert sorted(pd.read_csv(d / "jobs.csv")["status"]) == ["finished", "invalid", "invalid"]


def test_honest_rows_of_every_kind_pass(swept):
    for m in swept.rglob("metrics.json"):
        row = read_metrics_row(m)
        assert row["n_edges"] == len(row["edges"]) >= 0
