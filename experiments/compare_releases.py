"""Side by side against a recorded release: the benchmark's workload on two trees, in turn.

Checks out ``--base`` (a git ref) into a temporary worktree (``git worktree add --detach``; removed at
the end), and runs the same workload on it and on ``--head`` (default: this working tree, with its
uncommitted changes; or a git ref, checked out the same way). Every run is a fresh subprocess of the
same Python with ``PYTHONPATH`` set to one tree, and it drives that tree through its own scripts, so
a release that predates an API is measured with its own code:

* ``experiments/benchmark.py``'s cases (``--maps``, ``r = 0.2``, ``L_max = 10``): ``load_map`` and
  ``run_side_by_side`` with one repeat: (a) sequential HiGHS, (b) the batched PDHG path warm, its
  first run (compiling) and its compile seconds; and ``bench_transpose``: (d) the tube operator's
  and (e) the open-loop operator's ``K^T``, fused and derived;
* ``experiments/scaling.py``'s rows (``--rooms``: a seeded rooms map of about N cells;
  ``--grid4d``: a 4-D box grid of the double integrator), through its ``worker``: total seconds,
  the seconds before the first LP, the problem-building and solver seconds, compile seconds.

The sides alternate (base, head, then head, base, ...); ``--warmup`` rounds of the scaling rows run
first and are dropped (they fill the persistent compilation cache that the scaling rows use; the
benchmark's cases compile in every process, as ``experiments/benchmark.py`` does, and report it). The report gives
each phase's median seconds on both sides and the median of the per-round ratios head / base,
flags ratios above ``--tolerance``, and says for every case whether the two transition systems
are identical: the same edges ``(src, dst)`` with the same ``L`` (compared as files of sorted
``src dst L`` rows; HiGHS (a) and PDHG (b) of each benchmark map are compared too).

Usage
-----
python experiments/compare_releases.py --base 3fee900 --out outputs/compare   # table.md, runs.json, edges
python experiments/compare_releases.py --base 3fee900 --head HEAD --maps paper,large --grid4d 4444 --warmup 1
python experiments/compare_releases.py --base 3fee900 --maps paper --rooms '' --transpose '' --repeats 1

The defaults (``--maps paper --transpose paper --rooms 1000 --repeats 3``) make 6 runs; on a
2-core CPU shared with other work (load average 13 to 20) a run took about 5 minutes, the whole
comparison about 30 (about 2 minutes a run at a load near 1). ``--maps large`` adds about 5
minutes a run under that load, ``--grid4d 4444`` about 4 (the 4-D grid fills the compilation
cache on its first run, so add ``--warmup 1``). Exit status: 0 when every system is identical (the ratios are
reported, not judged), 1 otherwise, 2 when a run failed.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
RADIUS = 0.2
L_MAX = 10


# -- the worker: one tree, one fresh process -------------------------------------------------------

def _edges(ts) -> list:
    return [(e.src, e.dst, e.L) for e in ts.edges]


def _edge_file(edges, path: Path) -> dict:
    """Write ``(src, dst, L)`` edges as sorted ``src dst L`` rows; their count and sha256."""
    rows = sorted((int(s), int(d), int(L)) for s, d, L in edges)
    text = "".join(f"{s} {d} {L}\n" for s, d, L in rows)
    path.write_text(text)
    return {"edges": len(rows), "sha256": hashlib.sha256(text.encode()).hexdigest(), "file": str(path)}


def _bench_case(bench, name: str, out: Path, transpose: bool) -> tuple[dict, dict]:
    """One map of ``experiments/benchmark.py``: phases (seconds) and systems (edge files)."""
    import numpy as np
    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set

    decomp = bench.load_map(name)
    system = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, RADIUS))
    # the first seven values: a release's run_side_by_side may return more (its (a') runs, since removed)
    ts_h, ts_p, _, t_a, t_b, first, compile_s = bench.run_side_by_side(decomp, system, L_MAX, 1)[:7]
    phases = {f"{name} (a) HiGHS": t_a[0], f"{name} (b) PDHG warm": t_b[0],
              f"{name} (b) first run": first, f"{name} (b) compile": compile_s}
    systems = {f"{name} (a) HiGHS": _edge_file(_edges(ts_h), out / f"{name}-highs.txt"),
               f"{name} (b) PDHG": _edge_file(_edges(ts_p), out / f"{name}-pdhg.txt")}
    if transpose:
        with contextlib.redirect_stdout(sys.stderr):
            row = bench.bench_transpose(decomp, system, L_MAX, 3)
        for key, label in (("transpose", "(d) K^T"), ("openloop_transpose", "(e) open-loop K^T")):
            phases[f"{name} {label} fused"] = row[f"{key}_fused_seconds"]
            phases[f"{name} {label} derived"] = row[f"{key}_derived_seconds"]
    return phases, systems


def _scaling_case(scaling, kind: str, size: str, out: Path) -> tuple[dict, dict]:
    """One row of ``experiments/scaling.py`` (its ``worker``, the PDHG solver of conf/solver/pdhg.yaml)."""
    label = f"rooms:{size}" if kind == "grid2d" else f"4-D {size}"
    edges = out / f"{label.replace(':', '-').replace(' ', '')}.txt"
    spec = {"kind": kind, "size": int(size) if kind == "grid2d" else size, "seed": 0, "solver": "pdhg",
            "save_edges": str(edges) + ".raw"}
    with contextlib.redirect_stdout(sys.stderr):
        row = scaling.worker(spec)
    raw = [line.split() for line in Path(spec["save_edges"]).read_text().splitlines() if not line.startswith("#")]
    phases = {f"{label} total": row["seconds"], f"{label} before 1st LP": row["seconds_before_first_lp"],
              f"{label} problems": row["problem_seconds"], f"{label} solver": row["solve_seconds"],
              f"{label} compile": row["compile_seconds"]}
    return phases, {label: _edge_file(raw, edges)}


def worker(spec: dict) -> dict:
    """Run the workload of ``spec`` on the tree ``spec['tree']`` (already on ``sys.path``)."""
    import importlib

    import jax
    jax.config.update("jax_enable_x64", True)
    out = Path(spec["out"])
    out.mkdir(parents=True, exist_ok=True)
    phases, systems, walls = {}, {}, {}
    cases = []
    if spec["maps"]:
        bench = importlib.import_module("benchmark")
        cases += [(name, _bench_case, (bench, name, out, name in spec["transpose"])) for name in spec["maps"]]
    if spec["rooms"] or spec["grid4d"]:
        scaling = importlib.import_module("scaling")
        cases += [(f"{kind} {size}", _scaling_case, (scaling, kind, size, out))
                  for kind, sizes in (("grid2d", spec["rooms"]), ("grid4d", spec["grid4d"])) for size in sizes]
    for label, run, case_args in cases:
        t0 = time.perf_counter()
        p, s = run(*case_args)
        walls[label] = time.perf_counter() - t0
        phases.update(p)
        systems.update(s)
    return {"phases": phases, "systems": systems, "case_wall_seconds": walls}


def _worker_main(spec_file: str) -> int:
    spec = json.loads(Path(spec_file).read_text())
    tree = Path(spec["tree"]).resolve()
    # this script's folder must not shadow the tree's own experiments/ scripts
    sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != HERE]
    sys.path[:0] = [str(tree), str(tree / "experiments")]
    result = worker(spec)
    Path(spec["result"]).write_text(json.dumps(result, indent=1))
    return 0


# -- the driver ------------------------------------------------------------------------------------

def _git(*args: str) -> str:
    return subprocess.run(["git", "-C", str(ROOT), *args], check=True, capture_output=True, text=True).stdout.strip()


@contextlib.contextmanager
def _checkout(ref: str, tmp: Path, label: str):
    """A detached worktree of ``ref`` under ``tmp`` (removed afterwards)."""
    path = tmp / label
    _git("worktree", "add", "--detach", str(path), ref)
    try:
        yield path, _git("-C", str(path), "rev-parse", "--short", "HEAD")
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(path)], check=False)


def run_once(tree: Path, spec: dict, tag: str, tmp: Path, timeout: float) -> dict:
    """One fresh subprocess on ``tree``; its phases and systems."""
    spec = dict(spec, tree=str(tree), out=str(tmp / "edges" / tag), result=str(tmp / f"{tag}.json"))
    spec_file = tmp / f"{tag}.spec.json"
    spec_file.write_text(json.dumps(spec))
    env = dict(os.environ, PYTHONPATH=str(tree))
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker", str(spec_file)],
                          cwd=tree, env=env, capture_output=True, text=True, timeout=timeout)
    if proc.returncode != 0:
        raise RuntimeError(f"{tag}: the run on {tree} failed (exit {proc.returncode}):\n{proc.stderr[-4000:]}")
    result = json.loads(Path(spec["result"]).read_text())
    result["wall_seconds"] = time.perf_counter() - t0
    return result


def compare_systems(base: dict, head: dict) -> dict:
    """For each case: identical (same sha256 of the sorted edge rows) and, if not, the differences."""
    verdicts = {}
    for case in sorted(set(base) | set(head)):
        b, h = base.get(case), head.get(case)
        if b is None or h is None:
            verdicts[case] = {"identical": False, "why": "missing on one side"}
            continue
        v = {"identical": b["sha256"] == h["sha256"], "edges_base": b["edges"], "edges_head": h["edges"]}
        if not v["identical"]:
            eb = {tuple(r.split()) for r in Path(b["file"]).read_text().splitlines()}
            eh = {tuple(r.split()) for r in Path(h["file"]).read_text().splitlines()}
            v.update(only_base=len(eb - eh), only_head=len(eh - eb), example=sorted(eb ^ eh)[:5])
        verdicts[case] = v
    return verdicts


def summarise(rounds: list[dict], tolerance: float) -> list[dict]:
    """Per phase: median seconds on each side and the median of the per-round ratios head / base."""
    rows = []
    for phase in rounds[0]["base"]["phases"]:
        b = [r["base"]["phases"].get(phase) for r in rounds]
        h = [r["head"]["phases"].get(phase) for r in rounds]
        pairs = [(x, y) for x, y in zip(b, h) if x is not None and y is not None and x > 0]
        if not pairs:
            continue
        ratio = statistics.median(y / x for x, y in pairs)
        rows.append({"phase": phase, "base": statistics.median(x for x, _ in pairs),
                     "head": statistics.median(y for _, y in pairs), "ratio": ratio,
                     "base_all": [x for x, _ in pairs], "head_all": [y for _, y in pairs],
                     "over": ratio > 1 + tolerance})
    return rows


def table(rows: list[dict], verdicts: dict, meta: dict) -> str:
    lines = [f"base {meta['base']} vs head {meta['head']}; {meta['repeats']} interleaved rounds after "
             f"{meta['warmup']} warm-up; load average before {meta['load_before']}, after {meta['load_after']}; "
             f"{meta['minutes']:.1f} min", "",
             "| phase | base s (median) | head s (median) | head / base (median of rounds) |",
             "|---|---|---|---|"]
    for r in rows:
        flag = " **over**" if r["over"] else ""
        lines.append(f"| {r['phase']} | {r['base']:.3f} | {r['head']:.3f} | {r['ratio']:.2f}{flag} |")
    lines += ["", "| system | edges base | edges head | identical |", "|---|---|---|---|"]
    for case, v in verdicts.items():
        extra = "" if v.get("identical") else f" (only base {v.get('only_base')}, only head {v.get('only_head')})"
        lines.append(f"| {case} | {v.get('edges_base')} | {v.get('edges_head')} | {v['identical']}{extra} |")
    return "\n".join(lines)


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def parse_args(argv):
    ap = argparse.ArgumentParser(description="The benchmark's workload on a recorded release and on this tree, in turn")
    ap.add_argument("--base", required=True, help="git ref of the recorded release (e.g. 3fee900)")
    ap.add_argument("--head", default=None, help="git ref (default: this working tree as it is)")
    ap.add_argument("--maps", default="paper", help="experiments/benchmark.py maps ('' for none)")
    ap.add_argument("--rooms", default="1000", help="experiments/scaling.py rooms sizes, comma-separated")
    ap.add_argument("--grid4d", default="", help="experiments/scaling.py 4-D divisions, comma-separated")
    ap.add_argument("--transpose", default="paper", help="maps whose (d) and (e) run too ('' for none)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--warmup", type=int, default=0,
                    help="rounds of the scaling rows run first and dropped (they fill the compilation cache)")
    ap.add_argument("--tolerance", type=float, default=0.10, help="flag ratios above 1 + this")
    ap.add_argument("--timeout", type=float, default=1800, help="seconds per run")
    ap.add_argument("--out", type=Path, default=None, help="write table.md, runs.json and the edge files here")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    if argv is None and len(sys.argv) == 3 and sys.argv[1] == "--worker":
        return _worker_main(sys.argv[2])
    args = parse_args(argv)
    split = lambda s: [x for x in s.split(",") if x]                     # noqa: E731
    spec = {"maps": split(args.maps), "rooms": split(args.rooms), "grid4d": split(args.grid4d),
            "transpose": split(args.transpose)}
    warm = dict(spec, maps=[]) if spec["rooms"] or spec["grid4d"] else None
    t_start, load_before = time.perf_counter(), _load()
    with contextlib.ExitStack() as stack:
        tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="compare-releases-")))
        base_tree, base_rev = stack.enter_context(_checkout(args.base, tmp, "base"))
        if args.head is None:
            head_tree, head_rev = ROOT, _git("rev-parse", "--short", "HEAD") + " (working tree)"
        else:
            head_tree, head_rev = stack.enter_context(_checkout(args.head, tmp, "head"))
        rounds = []
        n_warm = args.warmup if warm else 0
        for k in range(n_warm + args.repeats):
            order = (("base", base_tree), ("head", head_tree))
            rnd = {}
            for side, tree in (order if k % 2 == 0 else order[::-1]):
                rnd[side] = run_once(tree, warm if k < n_warm else spec, f"{side}{k}", tmp, args.timeout)
                print(f"round {k}{' (warm-up)' if k < n_warm else ''} {side}: "
                      f"{rnd[side]['wall_seconds']:.1f} s, load {_load()}", flush=True)
            if k >= n_warm:
                rounds.append(rnd)
                if args.out:                          # so far, in case the comparison is cut short
                    args.out.mkdir(parents=True, exist_ok=True)
                    (args.out / "rounds.json").write_text(json.dumps(rounds, indent=1))
        last = rounds[-1]
        verdicts = compare_systems(last["base"]["systems"], last["head"]["systems"])
        for side in ("base", "head"):                 # HiGHS (a) against PDHG (b) on each side
            for m in spec["maps"]:
                s = last[side]["systems"]
                verdicts[f"{m}: (a) = (b) on {side}"] = {
                    "identical": s[f"{m} (a) HiGHS"]["sha256"] == s[f"{m} (b) PDHG"]["sha256"],
                    "edges_base": s[f"{m} (a) HiGHS"]["edges"], "edges_head": s[f"{m} (b) PDHG"]["edges"]}
        rows = summarise(rounds, args.tolerance)
        meta = {"base": base_rev, "head": head_rev, "repeats": args.repeats, "warmup": n_warm,
                "load_before": load_before, "load_after": _load(),
                "minutes": (time.perf_counter() - t_start) / 60, "python": sys.executable, "spec": spec}
        text = table(rows, verdicts, meta)
        print(text)
        if args.out:
            args.out.mkdir(parents=True, exist_ok=True)
            (args.out / "table.md").write_text(text + "\n")
            (args.out / "runs.json").write_text(json.dumps({"meta": meta, "rows": rows, "systems": verdicts,
                                                            "rounds": rounds}, indent=1))
            edges = args.out / "edges"
            edges.mkdir(exist_ok=True)
            for side in ("base", "head"):
                for case, s in last[side]["systems"].items():
                    (edges / f"{side}-{Path(s['file']).name}").write_text(Path(s["file"]).read_text())
    return 0 if all(v["identical"] for v in verdicts.values()) else 1


def _terminate(signum, frame):
    raise SystemExit(128 + signum)                  # so that the worktrees are removed


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, _terminate)
    try:
        sys.exit(main())
    except (RuntimeError, subprocess.CalledProcessError, subprocess.TimeoutExpired) as exc:
        print(f"compare_releases: {exc}", file=sys.stderr)
        sys.exit(2)
