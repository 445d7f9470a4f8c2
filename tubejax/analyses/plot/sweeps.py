"""Standard plots of a parameter sweep (a table from :func:`tubejax.analyses.sweep_results.collect_metrics`).

Nothing is merged or dropped silently: every setting that differs between jobs and is not on the
plot's axis keeps its rows apart, one line each, named in the legend. A *series* has one colour in
every plot (:func:`~tubejax.analyses.plot.style.series_colour`). :func:`available_plots` says which
plots have data.
"""

from __future__ import annotations

import itertools

import matplotlib.pyplot as plt
from matplotlib.ticker import MaxNLocator
import numpy as np
import pandas as pd

from ...lp.evidence.registry import exact_references, method_names, series_style, tube_methods
from ...lp.evidence.registry import series_name
from ..sweep_results import NOT_APPLICABLE, group_keys, short_names
from .style import series_colour

__all__ = ["series_name", "series_table", "line_groups", "available_plots", "plot_edges_vs_radius",
           "plot_conservatism", "plot_runtime", "plot_lmax", "PLOTS"]

_TUBE_MARKERS = ["o", "^", "D", "P", "X", "*", "h", "<"]
_GROUP_LINES = ["-", "--", ":", "-."]
_GROUP_MARKERS = ["o", "s", "^", "D", "v", "P", "X", "*", "h", "<"]
_SERIES_KEYS = ("method", "zshape")


def series_table(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` with a ``series`` column (:func:`series_name`)."""
    out = df.copy()
    out["series"] = [series_name(m, z) for m, z in zip(out["method"], out.get("zshape", [None] * len(out)))]
    out.attrs.update(df.attrs)
    return out


def _label(key: str, value, names: dict) -> str:
    if key == "workspace":
        return names.get(value, str(value))
    key = "r" if key == "radius" else key
    return f"{key}={value:g}" if isinstance(value, float) else f"{key}={value}"


def line_groups(df: pd.DataFrame, x: str, exclude=()) -> list[tuple[str, dict, pd.DataFrame]]:
    """The lines of a plot against ``x``: ``(legend label, matplotlib style, rows sorted by x)``,
    one per series and value of every other setting that differs between rows of ``df``."""
    t = series_table(df)
    keys = [k for k in group_keys(df) if k not in (x, *_SERIES_KEYS, *exclude)]
    names = short_names(t["workspace"]) if "workspace" in t else {}
    plain = frozenset(method_names()) - frozenset(tube_methods())      # named by their method alone (no Z)
    series = sorted(t["series"].unique(), key=lambda s: (s in plain, s))
    method = {s: _method_and_z(t, s) for s in series}
    tubes = [s for s in series if str(method[s][0]) in tube_methods()]
    if keys:
        combos = list(t[keys].drop_duplicates().sort_values(keys, kind="stable").itertuples(index=False, name=None))
        group_style = {c: dict(ls=_GROUP_LINES[k % len(_GROUP_LINES)], marker=_GROUP_MARKERS[k % len(_GROUP_MARKERS)])
                       for k, c in enumerate(combos)}
    else:
        combos = [()]
    out = []
    for s in series:
        record = series_style(method[s][0])
        marker = _TUBE_MARKERS[tubes.index(s) % len(_TUBE_MARKERS)] if s in tubes else record.marker
        colour = series_colour(*method[s])
        for c in combos:
            g = t[t["series"] == s]
            for k, v in zip(keys, c):
                g = g[(g[k].isna()) if (isinstance(v, float) and np.isnan(v)) else (g[k] == v)]
            if g.empty:
                continue
            if keys:
                style = dict(group_style[c], color=colour)
                parts = [_label(k, v, names) for k, v in zip(keys, c) if v != NOT_APPLICABLE]
                label = f"{s} · {', '.join(parts)}" if parts else s
            else:
                style = dict(ls=record.line, marker=marker, color=colour)
                label = s
            out.append((label, style, g.sort_values(x) if x in g else g))
    return out


def _method_and_z(t: pd.DataFrame, s: str):
    """The method and ``Z`` kind of series ``s`` (a row of ``t`` that carries it)."""
    row = t[t["series"] == s].iloc[0]
    return row["method"], row.get("zshape")


def _legend(ax, n: int):
    if n > 5:
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1.0), borderaxespad=0.0,
                  ncol=1 if n <= 24 else 2)
    else:
        ax.legend(fontsize=8)


def _n_values(df, col) -> int:
    return int(df[col].dropna().nunique()) if col in df else 0


def available_plots(df: pd.DataFrame) -> dict:
    """``{plot name: None}`` for the plots :data:`PLOTS` draws from ``df``, ``{name: why not}`` for the others.

    A plot against a setting needs two values of it; ``conservatism`` needs exact2d jobs and a
    job of another method at the same problem (:func:`tubejax.analyses.sweep_results.add_conservatism`).
    """
    out = {"edges_vs_radius": None if _n_values(df, "radius") >= 2 else
           f"one disturbance radius only ({df['radius'].dropna().unique().tolist() if 'radius' in df else []})"}
    reference = df["method"].isin(exact_references()) if "method" in df else pd.Series(False, index=df.index)
    if "conservatism" not in df or not reference.any():
        out["conservatism"] = "no exact2d jobs (add method=exact2d to the sweep)"
    elif not (df["conservatism"].notna() & ~reference).any():
        out["conservatism"] = "no job of another method shares a problem with an exact2d job"
    else:
        out["conservatism"] = out["edges_vs_radius"]
    out["lmax"] = None if _n_values(df, "L_max") >= 2 else "one L_max only"
    out["runtime"] = None if "solve_seconds" in df and df["solve_seconds"].notna().any() else "no runtimes"
    return out


def _lines_plot(df: pd.DataFrame, ax, x: str, y: str, ylabel: str, title: str):
    """``y`` against ``x`` (``'radius'`` or ``'L_max'``), one line per series and group, on ``ax`` or new axes."""
    ax = ax or plt.subplots(figsize=(5, 3.5))[1]
    lines = line_groups(df, x)
    for label, style, g in lines:
        ax.plot(g[x], g[y], label=label, **style)
    ax.grid(alpha=0.3)
    _legend(ax, len(lines))
    if x == "L_max":
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set(xlabel="disturbance size r" if x == "radius" else "L_max", ylabel=ylabel, title=title)
    return ax


def plot_edges_vs_radius(df: pd.DataFrame, ax=None):
    """Transitions found against ``r``: one line per series and group (every ``L_max`` its own)."""
    return _lines_plot(df, ax, "radius", "n_edges", "transitions", "transitions vs disturbance")


def plot_conservatism(df: pd.DataFrame, ax=None):
    """Edges found / exact2d edges against ``r`` (needs :func:`tubejax.analyses.sweep_results.add_conservatism`)."""
    sub = df[~df["method"].isin(exact_references()) & df["conservatism"].notna()]
    sub.attrs.update(df.attrs)
    ax = _lines_plot(sub, ax, "radius", "conservatism", "edges / exact edges",
                     "conservatism against the exact 2-D reference")
    ax.axhline(1.0, color="k", ls="--", lw=1)
    ax.set_ylim(-0.05, 1.05)
    return ax


def plot_lmax(df: pd.DataFrame, ax=None):
    """Transitions against ``L_max``: one line per series (every Z shape), radius and group."""
    return _lines_plot(df, ax, "L_max", "n_edges", "transitions", "effect of L_max")


def plot_runtime(df: pd.DataFrame, ax=None):
    """Solve time per job (``solve_seconds``, without JIT compiling) against ``r`` (else ``L_max``), with the
    lines, colours and labels of :func:`plot_edges_vs_radius`; with neither swept, against the number of
    problems solved, one marker per series and group."""
    x = next((c for c in ("radius", "L_max") if _n_values(df, c) >= 2), None)
    if x is not None:
        sub = df[df["solve_seconds"].notna()]
        sub.attrs.update(df.attrs)
        return _lines_plot(sub, ax, x, "solve_seconds", "solve seconds per job (without JIT compiling)", "runtime")
    ax = ax or plt.subplots(figsize=(5, 3.5))[1]
    t = series_table(df)
    keys = ["series"] + [k for k in group_keys(df) if k not in ("radius", "L_max", *_SERIES_KEYS)]
    names = short_names(t["workspace"]) if "workspace" in t else {}
    markers = itertools.cycle(["o", "s", "v", "^", "D", "P", "X", "*"])
    n = 0
    for key, g in t.groupby(keys, dropna=False, sort=True):
        key = key if isinstance(key, tuple) else (key,)
        label = " · ".join([str(key[0])] + [_label(k, v, names) for k, v in zip(keys[1:], key[1:])
                                             if v != NOT_APPLICABLE])
        ax.scatter(g["n_lps"], g["solve_seconds"], label=label, s=18, marker=next(markers),
                   color=series_colour(g["method"].iloc[0], g["zshape"].iloc[0] if "zshape" in g else None))
        n += 1
    ax.set(xlabel="problems solved", ylabel="seconds (without JIT compiling)", title="runtime")
    ax.grid(alpha=0.3)
    _legend(ax, n)
    return ax


#: The plots of ``experiments/aggregate.py``: ``{file name: function}``.
PLOTS = {"edges_vs_radius": plot_edges_vs_radius, "conservatism": plot_conservatism, "lmax": plot_lmax,
         "runtime": plot_runtime}
