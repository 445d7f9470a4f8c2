"""Collect sweep results into one table, say which jobs have none, and measure conservatism
(docs/howto/sweeps.md).

:func:`collect_metrics` gathers every job's ``metrics.json`` under a multirun directory with the
settings that vary between jobs, so rows of different settings are never mixed (:func:`group_keys`).
:func:`sweep_jobs` lists every job the sweep planned (``sweep.json``) or holds, with its status.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import yaml
from ..abstraction.runstore import run_state
from ..transitions.product_file import PRODUCT_STEM
from ..lp.evidence.registry import exact_references, ignored_settings, series_name
from .metrics_row import MetricsRowError, read_metrics_row

__all__ = ["collect_metrics", "collect_fraction_of_limit", "add_conservatism", "edge_sets", "group_keys", "sweep_jobs", "short_names",
           "problem_jobs", "GROUP_KEYS", "SETTING_COLUMNS", "NOT_APPLICABLE", "PLAN_FILE"]

#: Columns that identify one abstraction problem apart from the method and Z shape (the
#: ``exact2d`` reference of a row has the same values, :func:`add_conservatism`).
GROUP_KEYS = ["workspace", "system", "disturbance", "radius", "L_max"]
#: The columns of ``metrics.json`` that say what a job computed (the others are its results).
SETTING_COLUMNS = ["workspace", "system", "disturbance", "method", "zshape", "solver", "L_max", "pruning", "radius"]
#: The value of a setting the row's method ignores (:func:`~tubejax.lp.evidence.registry.ignored_settings`).
NOT_APPLICABLE = "-"
#: The sweep plan beside the job folders (``experiments/sweep_jobs.py``).
PLAN_FILE = "sweep.json"

#: Config keys (dotted) already said by a metrics column, or flags that never change a result.
_COVERED = {"method.name": "method", "zshape.kind": "zshape", "solver.name": "solver", "L_max": "L_max",
            "pruning": "pruning", "system.name": "system", "disturbance.kind": "disturbance",
            "disturbance.radius": "radius", "disturbance.half_width": "radius", "workspace.kind": "workspace",
            "workspace.map_file": "workspace", "workspace.file": "workspace"}
_FLAGS = ("progress", "resume", "overwrite", "figures")
#: What a finished job of each app wrote last.
_DONE_FILES = {"abstract": "metrics.json", "simulate": "simulation.json", "radius": "radius.json",
               "conservatism": "conservatism.json"}
#: Job statuses that mean "no result where one was expected" (``invalid``: its metrics.json cannot be
#: read or does not fit :class:`~tubejax.analyses.metrics_row.MetricsRow`).
PROBLEM_STATUSES = ("failed", "unfinished", "missing", "invalid")


def _flatten(d, prefix="") -> dict:
    out = {}
    if isinstance(d, dict):
        for k, v in d.items():
            out.update(_flatten(v, f"{prefix}.{k}" if prefix else str(k)))
    else:
        out[prefix] = json.dumps(d) if isinstance(d, (list, dict)) else d
    return out


def _job_root(path: Path, root: Path) -> Path | None:
    """The nearest folder at or above ``path`` (inside ``root``) holding Hydra's ``.hydra/``."""
    for d in (path, *path.parents):
        if (d / ".hydra" / "config.yaml").is_file():
            return d
        if d == root:
            break
    return None


def _job_config(job: Path | None) -> dict:
    if job is None:
        return {}
    try:
        c = yaml.safe_load((job / ".hydra" / "config.yaml").read_text())
    except (OSError, yaml.YAMLError):
        return {}
    return c if isinstance(c, dict) else {}


def _read_rows(root: Path, paths: list) -> tuple[list, list, list, dict]:
    """The valid ``metrics.json`` rows among ``paths`` with their jobs' settings (:func:`collect_metrics`):
    ``(rows, configs, known, invalid)``, ``known[k]`` whether row ``k``'s settings come from ``.hydra/``,
    ``invalid`` ``{job folder: why}`` of the rows left out."""
    rows, configs, known, invalid = [], [], [], {}
    for path in paths:
        try:
            row = read_metrics_row(path)
        except MetricsRowError as exc:
            invalid.setdefault(str(_job_root(path.parent, root) or path.parent), str(exc))
            continue
        row.pop("edges", None)
        row["job_dir"] = str(path.parent)
        ignored = ignored_settings(row.get("method"))
        for k in ignored:
            if k in row:
                row[k] = NOT_APPLICABLE
        job = _job_root(path.parent, root)
        known.append(job is not None)
        cfg = {k: v for k, v in _flatten(_job_config(job)).items()
               if k.split(".")[0] not in _FLAGS and not (k in _COVERED and _COVERED[k] in row)}
        cfg = {k: (NOT_APPLICABLE if k.split(".")[0] in ignored else v) for k, v in cfg.items()}
        rows.append(row)
        configs.append(cfg)
    return rows, configs, known, invalid


def collect_metrics(root, dedupe: bool = True) -> pd.DataFrame:
    """One row per ``metrics.json`` under ``root`` (searched recursively), with the swept settings.

    Besides the metrics columns (without the bulky ``edges``, :func:`edge_sets`) and ``job_dir``, every
    setting of the jobs' ``.hydra/config.yaml`` that differs between jobs (``min_margin``, ``zshape.scale``,
    ...) becomes a column named by its config key (listed in ``df.attrs["swept"]``). ``solve_seconds`` is
    ``seconds`` without the recorded JIT compile time. Settings a row's method ignores
    (:func:`~tubejax.lp.evidence.registry.ignored_settings`) read :data:`NOT_APPLICABLE`. With ``dedupe``,
    rows of Hydra jobs equal in every setting are kept once (the others' ``job_dir`` in
    ``df.attrs["duplicates"]``). A row that fails :func:`~tubejax.analyses.metrics_row.read_metrics_row`
    is left out and named in ``df.attrs["invalid"]`` (``{job folder: why}``), never dropped silently.

    Returns
    -------
    pandas.DataFrame
        Sorted by :func:`group_keys`, then method, zshape, radius, L_max.

    Raises
    ------
    FileNotFoundError
        No ``metrics.json`` under ``root``.
    """
    root = Path(root)
    paths = sorted(root.rglob("metrics.json"))
    rows, configs, known, invalid = _read_rows(root, paths)
    if not paths:
        raise FileNotFoundError(f"{root}: no metrics.json found (run a sweep with experiments/abstract.py -m)")
    if not rows:
        df = pd.DataFrame(columns=["method", "job_dir"])
        df.attrs.update(swept=[], duplicates=[], invalid=invalid)
        return df
    df = pd.DataFrame(rows)
    cfg = pd.DataFrame(configs, index=df.index)
    swept = [k for k in cfg.columns if k not in df.columns and _varies(cfg[k])]
    for k in swept:
        df[k] = cfg[k]
    if "seconds" in df:
        df["solve_seconds"] = df["seconds"] - (df["compile_seconds"].fillna(0.0) if "compile_seconds" in df else 0.0)
    dups = []
    if dedupe:
        keys = [k for k in SETTING_COLUMNS + swept if k in df]
        mask = df[keys].astype(str).duplicated(keep="first") & pd.Series(known, index=df.index)
        dups = df.loc[mask, "job_dir"].tolist()
        df = df[~mask]
    order = [k for k in group_keys(df) if k not in ("method", "zshape", "radius", "L_max")]
    order += [k for k in ("method", "zshape", "radius", "L_max") if k in df]
    if order:
        df = df.sort_values(order, kind="stable", key=lambda s: s.astype(str) if s.dtype == object else s)
    df = df.reset_index(drop=True)
    df.attrs.update(swept=swept, duplicates=dups, invalid=invalid)
    return df


def group_keys(df: pd.DataFrame) -> list[str]:
    """The settings that differ between rows of ``df`` (:data:`SETTING_COLUMNS`, then ``df.attrs["swept"]``;
    :data:`NOT_APPLICABLE` is no value of its own): a plot keeps rows of different values apart."""
    cols = [k for k in SETTING_COLUMNS if k in df] + [k for k in df.attrs.get("swept", []) if k in df]
    return [k for k in cols if _varies(df[k])]


def _varies(values: pd.Series) -> bool:
    """More than one value, :data:`NOT_APPLICABLE` aside (a method that ignores a setting)."""
    text = values.map(lambda v: json.dumps(v, default=str))
    return text[text != json.dumps(NOT_APPLICABLE)].nunique(dropna=False) > 1


def short_names(values) -> dict:
    """``{value: label}``: a file path by its name without suffix where that is unique among
    ``values``, else by its last two path parts; other values unchanged (as text)."""
    vals = [v for v in dict.fromkeys(values)]
    out = {v: str(v) for v in vals}
    paths = [v for v in vals if isinstance(v, str) and ("/" in v or "\\" in v)]
    for depth in (1, 2, 3):
        labels = {v: ("/".join(Path(v).parts[-depth:]) if depth > 1 else Path(v).stem) for v in paths}
        if len(set(labels.values())) == len(paths):
            out.update(labels)
            break
    return out


def edge_sets(root) -> dict:
    """``{job_dir: {(src, dst): L}}`` for every job under ``root``: the ``edges`` of its ``metrics.json``, or,
    for a product run (whose metrics only count them), the edge arrays of its ``product_transitions.npz``."""
    out = {}
    for path in sorted(Path(root).rglob("metrics.json")):
        data = json.loads(path.read_text())
        edges = data.get("edges")
        npz = path.parent / f"{PRODUCT_STEM}.npz"
        if edges is None and data.get("product") and npz.is_file():
            with np.load(npz, allow_pickle=False) as z:
                edges = zip(z["edge_src"].tolist(), z["edge_dst"].tolist(), z["edge_L"].tolist())
        out[str(path.parent)] = {(a, b): L for a, b, L in (edges or [])}
    return out


#: Settings that never change the exact 2-D reference (not matched when a row looks for it).
_EXACT_IGNORES = ("zshape", "eps_min", "solver", "min_margin", "verify", "memory_budget_mb", "seed", "pruning")


def add_conservatism(df: pd.DataFrame) -> pd.DataFrame:
    """Add ``exact_edges`` and ``conservatism`` = edges found / exact2d edges.

    The exact reference of a row is the ``exact2d`` job with the same :data:`GROUP_KEYS` and
    the same values of the other swept settings that exact2d depends on; rows without one get NaN.
    """
    swept = [k for k in df.attrs.get("swept", []) if k in df and k.split(".")[0] not in _EXACT_IGNORES]
    keys = [k for k in GROUP_KEYS if k in df] + swept
    attrs = dict(df.attrs)
    exact = df[df["method"].isin(exact_references())]
    if exact.empty:
        out = df.assign(exact_edges=float("nan"), conservatism=float("nan"))
    else:
        ref = exact.groupby(keys, dropna=False)["n_edges"].max().rename("exact_edges")
        out = df.join(ref, on=keys)
        out["conservatism"] = out["n_edges"] / out["exact_edges"]
    out.attrs.update(attrs)
    return out


def _app(cfg: dict) -> str:
    return ("radius" if "radii" in cfg else "simulate" if "sim" in cfg else "conservatism" if "methods" in cfg
            else "abstract")


def _error_line(job: Path) -> str:
    """The last error a job logged (``[ERROR] - ...`` in ``job/*.log``), or ``''``."""
    found = ""
    for log in sorted(job.glob("*.log")):
        try:
            for line in log.read_text(errors="replace").splitlines():
                m = re.search(r"\[ERROR\] - (.*)", line)
                if m:
                    found = f"{m.group(1).strip()} (log: {log})"
        except OSError:
            continue
    return found


def _status(job: Path) -> tuple[str, str]:
    if not job.is_dir():
        return "missing", "never ran"
    done = _DONE_FILES[_app(_job_config(job))]
    if (job / done).is_file():
        return "finished", ""
    if run_state(job) == "partial":
        return "unfinished", f"interrupted or still running (continue it with resume=true); no {done}"
    err = _error_line(job)
    return "failed", err or f"no {done} and no error in its log (killed, or stopped with the sweep)"


def _display(overrides: list[str], varying: set[str]) -> str:
    shown = [o for o in overrides if o.split("=", 1)[0].lstrip("+~") in varying]
    return " ".join(shown or overrides) or "(no overrides)"


def sweep_jobs(root, expected: list[tuple[str, list[str]]] | None = None, table: pd.DataFrame | None = None
               ) -> pd.DataFrame:
    """Every job of the sweep in ``root`` and whether it has its result.

    The jobs are those of the plan ``root/sweep.json``, else ``expected`` (``(folder, overrides)`` pairs
    from Hydra's ``multirun.yaml``), and every job folder found (with ``.hydra/``). With ``table``
    (:func:`collect_metrics` of ``root``) a job whose metrics.json it refused is ``invalid`` and the
    column ``summary_rows`` counts the job's rows in it.

    Returns
    -------
    pandas.DataFrame
        Columns ``job`` (the overrides that differ between jobs), ``dir``, ``status`` --
        ``finished``, ``skipped`` (a duplicate: ``detail`` names the job that computes it),
        ``failed`` (``detail``: the error the job logged), ``unfinished`` (interrupted or still
        running), ``missing`` (planned, never started), ``invalid`` (with ``table``) -- and
        ``detail`` (and ``summary_rows`` with ``table``).
    """
    root = Path(root)
    jobs: dict[str, dict] = {}
    try:
        plan = json.loads((root / PLAN_FILE).read_text()).get("jobs", {})
    except (OSError, ValueError, AttributeError):           # no plan, or not one
        plan = {}
    for name, e in plan.items():
        jobs[name] = {"overrides": list(e.get("overrides") or []), "plan": e.get("status"),
                      "same_as": e.get("same_as"), "reason": e.get("reason", "")}
    if not plan:
        for name, ov in expected or []:
            jobs.setdefault(name, {"overrides": list(ov), "plan": "run"})
    for h in sorted(root.rglob(".hydra")):
        d = h.parent
        if not (h / "config.yaml").is_file() or d == root:
            continue
        name = str(d.relative_to(root))
        if name not in jobs:
            try:
                ov = yaml.safe_load((h / "overrides.yaml").read_text()) or []
            except (OSError, yaml.YAMLError):
                ov = []
            jobs[name] = {"overrides": [str(o) for o in ov] if isinstance(ov, list) else [], "plan": None}
    keys: dict[str, set] = {}
    for j in jobs.values():
        for o in j["overrides"]:
            k, _, v = o.partition("=")
            keys.setdefault(k.lstrip("+~"), set()).add(v)
    varying = {k for k, vs in keys.items() if len(vs) > 1 or any(k not in {
        o.partition("=")[0].lstrip("+~") for o in j["overrides"]} for j in jobs.values())}
    rows = []
    for name, j in jobs.items():
        if j["plan"] == "duplicate":
            status = "skipped"
            detail = f"same as {j.get('same_as')}" + (f" ({j['reason']})" if j.get("reason") else "")
        else:
            status, detail = _status(root / name)
        rows.append({"job": _display(j["overrides"], varying), "dir": str(root / name), "status": status,
                     "detail": detail})
    out = pd.DataFrame(rows, columns=["job", "dir", "status", "detail"])
    return out if table is None else _agree_with(out, table, root)


def _agree_with(jobs: pd.DataFrame, table: pd.DataFrame, root: Path) -> pd.DataFrame:
    """``jobs`` with the invalid ones marked and each job's count of rows in ``table``."""
    jobs = jobs.copy()
    invalid = table.attrs.get("invalid", {})
    dups = set(table.attrs.get("duplicates", []))
    dirs = [Path(d) for d in table["job_dir"]] if len(table) else []

    def rows_of(d: str) -> int:
        return sum(1 for j in dirs if j == Path(d) or Path(d) in j.parents)

    for k, r in jobs.iterrows():
        if r["dir"] in invalid:
            jobs.loc[k, ["status", "detail"]] = ["invalid", invalid[r["dir"]]]
        elif r["status"] == "finished" and not rows_of(r["dir"]) and any(
                Path(x) == Path(r["dir"]) or Path(r["dir"]) in Path(x).parents for x in dups):
            jobs.loc[k, "detail"] = "its row equals another job's (a setting its method ignores): kept once"
    for d, why in invalid.items():                        # a metrics.json outside any listed job folder
        if d not in set(jobs["dir"]):
            jobs.loc[len(jobs)] = [str(Path(d).relative_to(root)) if Path(d).is_relative_to(root) else d, d,
                                   "invalid", why]
    jobs["summary_rows"] = [rows_of(d) for d in jobs["dir"]]
    return jobs


def problem_jobs(jobs: pd.DataFrame) -> pd.DataFrame:
    """The rows of :func:`sweep_jobs` without a result: failed, unfinished or never run."""
    return jobs[jobs["status"].isin(PROBLEM_STATUSES)]


#: Config keys that are the x-axis or the series of the fraction-of-limit plot, not a group.
_LIMIT_AXES = ("disturbance.radius", "disturbance.half_width", "zshape.kind", "method.name", "methods")
#: Config keys that say where a job read its runs from (``abstraction_dirs.tube``, ...), not what it solved.
_LIMIT_SOURCES = ("abstraction_dirs",)


def collect_fraction_of_limit(root) -> pd.DataFrame:
    """One row per job and method of every ``conservatism.json`` under ``root`` (``experiments/conservatism.py``).

    Columns ``job_dir``, ``radius`` (or the box's half-width), ``method``, ``series``, ``fraction_of_limit``
    (NaN when the limit did not converge), ``converged``, ``winning_area``, ``limit_area``, ``free_area``
    and ``group``: the other settings that differ between jobs (``L_max=...``; ``''`` when none do).
    """
    rows, configs = [], []
    for path in sorted(Path(root).rglob("conservatism.json")):
        try:
            doc = json.loads(path.read_text())
            methods = doc["methods"]
        except (OSError, ValueError, KeyError, TypeError):
            continue
        cfg = _flatten(_job_config(_job_root(path.parent, Path(root))))
        radius = cfg.get("disturbance.radius", cfg.get("disturbance.half_width", float("nan")))
        lim = doc.get("limit", {})
        for method, m in methods.items():
            frac = m.get("fraction_of_limit")
            rows.append({"job_dir": str(path.parent), "radius": float(radius), "method": method,
                         "series": series_name(method, cfg.get('zshape.kind', '?')),
                         "fraction_of_limit": float("nan") if frac is None or not lim.get("converged") else frac,
                         "converged": bool(lim.get("converged")), "winning_area": m.get("winning_area"),
                         "limit_area": lim.get("area"), "free_area": doc.get("free_area")})
            configs.append({k: v for k, v in cfg.items() if k.split(".")[0] not in _FLAGS + _LIMIT_SOURCES and k not in _LIMIT_AXES})
    df = pd.DataFrame(rows)
    if df.empty:
        return df
    cfg = pd.DataFrame(configs, index=df.index)
    varying = [k for k in cfg.columns if _varies(cfg[k])]
    df["group"] = [", ".join(f"{k}={cfg.at[i, k]}" for k in varying) for i in df.index]
    return df.sort_values(["group", "series", "radius"], kind="stable").reset_index(drop=True)
