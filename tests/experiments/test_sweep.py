"""A small Hydra multirun sweep, aggregated into a table with one row per job."""

import subprocess
import sys
from pathlib import Path

import pandas as pd

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / "tests" / "data" / "tiny.txt"


def test_multirun_sweep_and_aggregate(tmp_path):
    sweep = tmp_path / "sweep"
    p = subprocess.run([sys.executable, str(ROOT / "experiments" / "abstract.py"), "-m", "progress=false", "solver=highs",
                        f"workspace.map_file={TINY}", "hydra/launcher=parallel", "disturbance.radius=0,0.2", "method=tube,openloop,exact2d",
                        "L_max=6", f"hydra.sweep.dir={sweep}"], capture_output=True, text=True, timeout=900)
    assert p.returncode == 0, p.stderr[-3000:]
    assert len(list(sweep.rglob("metrics.json"))) == 6
    assert len(list(sweep.rglob("transitions.json"))) == 6
    a = subprocess.run([sys.executable, str(ROOT / "experiments" / "aggregate.py"), str(sweep)],
                       capture_output=True, text=True, timeout=300)
    assert a.returncode == 0, a.stderr[-3000:]
    df = pd.read_csv(sweep / "summary.csv")
    assert len(df) == 6 and set(df["method"]) == {"tube", "openloop", "exact2d"}
    ex = df[df["method"] == "exact2d"].set_index("radius")["n_edges"]
    for _, row in df.iterrows():                      # exact2d bounds every method's edge count
        assert row["n_edges"] <= ex[row["radius"]]
        assert 0 <= row["conservatism"] <= 1
    ol = df[df["method"] == "openloop"].set_index("radius")["n_edges"]
    assert ol[0.2] <= ol[0.0]
    for name in ("edges_vs_radius", "conservatism", "lmax", "runtime"):
        assert (sweep / "plots" / f"{name}.png").stat().st_size > 5000


def test_aggregate_refuses_an_empty_directory(tmp_path):
    a = subprocess.run([sys.executable, str(ROOT / "experiments" / "aggregate.py"), str(tmp_path)],
                       capture_output=True, text=True, timeout=300)
    assert a.returncode == 2 and "no metrics.json found" in a.stderr
