"""Collect a multirun directory into one table and draw the standard plots.

Usage
-----
python experiments/aggregate.py multirun/2026-11-22/17-00-00
    -> summary.csv and plots/*.png (+ .pdf) inside that directory.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from tubejax.analysis import add_conservatism, collect_metrics  # noqa: E402
from tubejax.plot import sweeps  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import ArgumentParser  # noqa: E402


def main(argv=None) -> int:
    ap = ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sweep_dir", type=Path, help="a Hydra multirun directory (holds one folder per job)")
    ap.add_argument("--out", type=Path, default=None, help="where to write (default: the sweep directory)")
    args = ap.parse_args(argv)
    if not args.sweep_dir.is_dir():
        print(f"error: sweep_dir {args.sweep_dir} is not a directory", file=sys.stderr)
        return 2
    try:
        df = add_conservatism(collect_metrics(args.sweep_dir))
    except FileNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    out = args.out or args.sweep_dir
    (out / "plots").mkdir(parents=True, exist_ok=True)
    df.to_csv(out / "summary.csv", index=False)
    for name, fn in [("edges_vs_radius", sweeps.plot_edges_vs_radius),
                     ("conservatism", sweeps.plot_conservatism),
                     ("lmax", sweeps.plot_lmax), ("runtime", sweeps.plot_runtime)]:
        fig, ax = plt.subplots(figsize=(5.5, 3.8))
        fn(df, ax=ax)
        fig.tight_layout()
        for ext in ("png", "pdf"):
            fig.savefig(out / "plots" / f"{name}.{ext}", dpi=120)
        plt.close(fig)
    cols = ["method", "zshape", "radius", "L_max", "n_edges", "conservatism", "seconds"]
    print(df[cols].to_string(index=False))
    print(f"\n{len(df)} jobs -> {out / 'summary.csv'} and {out / 'plots'}/")
    return 0


if __name__ == "__main__":
    sys.exit(main())
