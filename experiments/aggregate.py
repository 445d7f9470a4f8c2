"""Collect a multirun directory into one table and draw the standard plots.

Usage
-----
python experiments/aggregate.py multirun/2026-11-22/17-00-00
    -> summary.csv, jobs.csv and plots/*.png (+ .pdf) inside that directory.

Nothing is merged silently:

* ``summary.csv`` has one row per distinct job, with every setting that differs between jobs
  (workspace, system, method, zshape, L_max, radius, and any other swept key such as
  ``min_margin``) as a column; ``zshape`` (and exact2d's ``solver``) read ``-`` for the methods
  that ignore them, and rows repeated over such a setting are kept once. ``solve_seconds`` is
  the run time without JIT compiling.
* The plots draw one line per method (and Z shape for tubes) and per value of every other
  swept setting, named in the legend; a plot without data (``conservatism`` without exact2d
  jobs, ``lmax`` with one ``L_max``) is not drawn and its old file is removed.
* Every job's ``metrics.json`` is validated before it is used (schema and ranges:
  :mod:`tubejax.analyses.metrics_row`): a cut file, a string where a number belongs or a negative
  count makes the job ``invalid``, named with the file and field.
* ``jobs.csv`` lists every job of the sweep (``sweep.json``, the plan written before the first
  job, else Hydra's ``multirun.yaml``) with its status and its number of rows in ``summary.csv``
  (``summary_rows``), so the two files agree. A job that failed, is unfinished, never ran or is
  invalid is named on stderr with its error, and the exit code is 1 with nothing else written,
  unless ``--allow-missing`` (then the figures say how many jobs are missing).
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from tubejax.analyses.sweep_results import (add_conservatism, collect_fraction_of_limit, collect_metrics,  # noqa: E402
                                            group_keys, problem_jobs, short_names, sweep_jobs)
from tubejax.analyses.plot.conservatism import plot_fraction_of_limit  # noqa: E402
from tubejax.analyses.plot import figure_style, save_figure, sweeps  # noqa: E402

EXIT_MISSING = 1


def expected_jobs(sweep_dir: Path) -> list[tuple[str, list[str]]] | None:
    """The job folders and overrides Hydra's ``multirun.yaml`` in ``sweep_dir`` implies (the last
    sweep into it), for sweeps without a ``sweep.json`` plan; ``None`` when they cannot be told."""
    path = sweep_dir / "multirun.yaml"
    if not path.is_file():
        return None
    try:
        from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
        from hydra.core.override_parser.overrides_parser import OverridesParser
        from hydra._internal.config_loader_impl import get_overrides_dirname
        from omegaconf import OmegaConf

        cfg = OmegaConf.load(path)
        params = OmegaConf.select(cfg, "hydra.sweeper.params") or {}
        args = [f"{k}={v}" for k, v in params.items()] + list(cfg.hydra.overrides.task)
        parser = OverridesParser.create()
        jobs = [list(j) for b in BasicSweeper.split_arguments(parser.parse_overrides(args), None) for j in b]
        subdir = str(cfg.hydra.sweep._get_node("subdir")._value())
        if subdir == "${hydra.job.num}":
            return [(str(k), j) for k, j in enumerate(jobs)]
        if "tubejax.job_dir" in subdir:
            sys.path.insert(0, str(Path(__file__).resolve().parent))
            from sweep_jobs import job_dir_name

            return [(job_dir_name(j), j) for j in jobs]
        if "override_dirname" in subdir:
            od = cfg.hydra.job.config.override_dirname
            return [(get_overrides_dirname(parser.parse_overrides(j), list(od.exclude_keys), od.item_sep,
                                           od.kv_sep), j) for j in jobs]
    except Exception:                      # an old or hand-edited multirun.yaml: only the folders found count
        return None
    return None


def _jobs(n: int, what: str = "") -> str:
    return f"{n} {what}job{'' if n == 1 else 's'}"


def report_jobs(jobs, out=sys.stderr) -> int:
    """Print the jobs without a result (one line each); returns how many."""
    bad = problem_jobs(jobs)
    if len(bad):
        n_fin = int((jobs["status"] == "finished").sum())
        n_dup = int((jobs["status"] == "skipped").sum())
        print(f"warning: {len(bad)} of {len(jobs)} jobs have no result ({n_fin} finished"
              + (f", {n_dup} skipped as duplicates" if n_dup else "") + "):", file=out)
        for _, r in bad.iterrows():
            what = {"missing": "never ran", "failed": "failed", "unfinished": "unfinished",
                    "invalid": "invalid"}[r["status"]]
            detail = "" if r["status"] == "missing" else f": {r['detail']}"
            print(f"warning:   {what:10s} {r['job']}{detail}", file=out)
    return len(bad)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import ArgumentParser  # noqa: E402


def main(argv=None) -> int:
    ap = ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sweep_dir", type=Path, help="a Hydra multirun directory (holds one folder per job)")
    ap.add_argument("--out", type=Path, default=None, help="where to write (default: the sweep directory)")
    ap.add_argument("--allow-missing", action="store_true",
                    help="aggregate the finished jobs although others failed, are unfinished or never ran "
                         "(they are still named on stderr)")
    args = ap.parse_args(argv)
    if not args.sweep_dir.is_dir():
        print(f"error: sweep_dir {args.sweep_dir} is not a directory", file=sys.stderr)
        return 2
    limits = collect_fraction_of_limit(args.sweep_dir)
    try:
        df = collect_metrics(args.sweep_dir)
    except FileNotFoundError as exc:
        report_jobs(sweep_jobs(args.sweep_dir, expected_jobs(args.sweep_dir)))
        print(f"error: {exc}", file=sys.stderr)
        return 2
    jobs = sweep_jobs(args.sweep_dir, expected_jobs(args.sweep_dir), table=df)
    n_bad = report_jobs(jobs)
    if not len(df):
        print(f"error: no job of {args.sweep_dir} has a valid metrics.json (each is named above); nothing to "
              "aggregate", file=sys.stderr)
        return EXIT_MISSING
    df = add_conservatism(df)
    if n_bad and not args.allow_missing:
        n_fin = int((jobs["status"] == "finished").sum())
        print(f"error: {_jobs(n_bad)} of {args.sweep_dir} {'has' if n_bad == 1 else 'have'} no result; rerun "
              f"{'it' if n_bad == 1 else 'them'} (resume=true continues unfinished jobs, finished jobs are skipped), "
              f"or pass --allow-missing to aggregate the {_jobs(n_fin, 'finished ')} anyway", file=sys.stderr)
        return EXIT_MISSING
    out = args.out or args.sweep_dir
    plots = out / "plots"
    plots.mkdir(parents=True, exist_ok=True)
    df.to_csv(out / "summary.csv", index=False)
    jobs.to_csv(out / "jobs.csv", index=False)
    note = f"incomplete sweep: {n_bad} of {len(jobs)} jobs without a result" if n_bad else None
    drawn = []
    for name, why in sweeps.available_plots(df).items():
        if why is not None:
            for ext in ("png", "pdf"):
                (plots / f"{name}.{ext}").unlink(missing_ok=True)      # never leave a stale figure behind
            print(f"{name}: not drawn ({why})")
            continue
        with figure_style("paper"):                  # drawn in the style, one colour per method and Z
            fig, ax = plt.subplots(figsize=(5.5, 3.8))
            sweeps.PLOTS[name](df, ax=ax)
            if note:
                fig.text(0.01, 0.005, note, fontsize=7, color="#D55E00", va="bottom")
            fig.tight_layout()
            save_figure(fig, plots, name, dpi=120)
        plt.close(fig)
        drawn.append(name)
    if not limits.empty:
        limits.to_csv(out / "fraction_of_limit.csv", index=False)
        fig, ax = plt.subplots(figsize=(5.5, 3.8))
        plot_fraction_of_limit(limits, ax=ax)
        if note:
            fig.text(0.01, 0.005, note, fontsize=7, color="tab:red", va="bottom")
        fig.tight_layout()
        save_figure(fig, plots, "fraction_of_limit", dpi=120)
        plt.close(fig)
        drawn.append("fraction_of_limit")
        print(limits[["group", "series", "radius", "fraction_of_limit", "converged"]].to_string(index=False))
    keys = group_keys(df)
    cols = [k for k in keys if k not in ("method", "zshape", "radius", "L_max")]
    cols += [c for c in ("method", "zshape", "radius", "L_max", "n_edges", "conservatism", "solve_seconds") if c in df]
    table = df[cols].copy()
    if "workspace" in table:
        table["workspace"] = table["workspace"].map(short_names(table["workspace"]))
    print(table.to_string(index=False))
    dups = df.attrs.get("duplicates", [])
    print(f"\n{_jobs(len(df))}" + (f" ({len(dups)} duplicate rows dropped: methods that ignore a setting, run "
                                 f"once per value of it)" if dups else "")
          + f" -> {out / 'summary.csv'}, {out / 'jobs.csv'} and {plots}/ ({', '.join(drawn) or 'no plots'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
