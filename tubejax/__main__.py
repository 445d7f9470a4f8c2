"""Command line: ``python -m tubejax verify DIR [--complete] [--stem NAME] [--no-exact]`` and
``python -m tubejax export-controller DIR --to c,python (--sequence 1,3,4 | --formula F | --ltl F | --patrol 3,5)``.

Exit status of ``verify``: 0 verified; 1 something failed verification (each finding on its own line);
2 a usage error. Of ``export-controller``: 0 written; 1 no plan, or an edge whose evidence fails;
2 a usage error or bad input.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from .analyses.control import PlanningError
from .analyses.control.export import LANGUAGES, WEIGHTS
from .analyses.spec import plan_patrol
from .api import load
from .api_control import EVIDENCE_FAILS, _start_cell, export_controller, plan as make_plan
from .errors import InputError
from .verify.verifier import verify_directory

__all__ = ["main", "verify_main", "export_main"]
USAGE = ("usage: python -m tubejax verify DIR [--complete] [--sample K] [--stem NAME] [--no-exact] [--trust-file-data]\n"
         "       python -m tubejax export-controller DIR --to c,python (--sequence 1,3,4 | --formula F | "
         "--ltl F | --patrol 3,5) [--start CELL] [--out DIR]")


def _parser(prog: str, description: str) -> argparse.ArgumentParser:
    """A parser with what both commands take: the run directory and the file stem."""
    p = argparse.ArgumentParser(prog=prog, description=description)
    p.add_argument("directory", help="the run directory holding <stem>.json and <stem>.npz")
    p.add_argument("--stem", default="transitions", help="file stem (default: transitions)")
    return p


def _verify_parser(prog: str) -> argparse.ArgumentParser:
    p = _parser(prog, "Prove a saved transition system from its sources: rebuild the problem from the recorded "
                "inputs, re-check every edge's evidence (float64 and exact), and optionally re-solve every non-edge.")
    p.add_argument("--complete", action="store_true",
                   help="also re-solve every non-edge up to L_max with HiGHS (finds deleted edges)")
    p.add_argument("--sample", type=int, default=50, metavar="K",
                   help="a product run with --complete: how many full pairs to re-solve as joint LPs (default 50)")
    p.add_argument("--no-exact", action="store_true", help="skip re-proving the exact (rational) proofs")
    p.add_argument("--trust-file-data", action="store_true",
                   help="for a file without an inputs record: check it against its own copied data")
    p.add_argument("--quiet", action="store_true", help="print only findings and the verdict")
    return p


def verify_main(argv=None, prog: str = "tubejax-verify") -> int:
    """Run the verifier; returns the exit status."""
    args = _verify_parser(prog).parse_args(argv)
    rep = verify_directory(args.directory, args.stem, complete=args.complete, exact=not args.no_exact,
                           progress=not args.quiet, trust_file_data=args.trust_file_data, sample=args.sample)
    for f in rep.findings:
        print(f"FAIL {f}")
    if rep.ok:
        c = rep.proof_counts
        levels = ", ".join(f"{v} {k}" for k, v in c.items() if v)
        print(f"verify OK: {rep.headline}")
        print(f"  {rep.n_edges} edges ({levels or 'none'}) {rep.summary} [{rep.seconds:.1f} s]")
        for note in rep.notes:
            print(f"  {note}")
        return 0
    print(f"verify FAILED: {len(rep.findings)} finding{'s' if len(rep.findings) != 1 else ''} in {args.directory}")
    return 1


def _export_parser(prog: str) -> argparse.ArgumentParser:
    p = _parser(prog, "Plan over a saved transition system and write the plan's controller as dependency-free "
                "code: C99 needing only libm, and/or a module needing only NumPy (docs/howto/export.md).")
    p.add_argument("--to", default="c,python", help="comma-separated languages among c, python (default: both)")
    p.add_argument("--out", default=None, help="where to write (default: DIR/controller)")
    spec = p.add_mutually_exclusive_group(required=True)
    spec.add_argument("--sequence", help="comma-separated region labels: start in the first, visit the others in order")
    spec.add_argument("--formula", help="an LTLf formula over l<label>, e.g. 'F(l3 & F l5) & G(!l4)' (needs --start)")
    spec.add_argument("--ltl", help="an LTL formula over infinite runs, e.g. 'GF l3 & GF l6 & G !l4' (needs "
                      "--start): its lasso's cycle repeats")
    spec.add_argument("--patrol", help="comma-separated region labels patrolled in a cycle (needs --start)")
    p.add_argument("--start", default=None, help="start cell id, or a region label (its first cell)")
    p.add_argument("--avoid", default="", help="patrol: comma-separated labels of regions no tube may meet")
    p.add_argument("--cycles", type=int, default=None, help="patrol, ltl: how often the cycle runs (default: forever)")
    p.add_argument("--planner", default="exact", help="sequence planner: exact, greedy or product")
    p.add_argument("--weights", default="triangulation", choices=list(WEIGHTS),
                   help="the step's weights: the library's triangulation (default), or multilinear on box sets")
    return p


def _labels(text: str) -> list:
    return [t.strip() for t in text.split(",") if t.strip()]


def _start(start):
    """``--start``: a cell id (digits) or a region label."""
    return int(start) if start is not None and start.isdigit() else start


def export_main(argv=None, prog: str = "tubejax-export-controller") -> int:
    """Plan and export a controller; returns the exit status."""
    args = _export_parser(prog).parse_args(argv)
    langs = _labels(args.to)
    if not langs or any(l not in LANGUAGES for l in langs):
        print(f"error: --to: expected comma-separated languages among {', '.join(LANGUAGES)}, got {args.to!r}",
              file=sys.stderr)
        return 2
    try:
        ts = load(args.directory, args.stem)
        start = _start(args.start)
        if start is None and (args.patrol is not None or args.ltl is not None):
            raise InputError(f"--start: {'a patrol' if args.patrol is not None else 'an LTL formula'} needs a start "
                             "cell (a cell id, or a region label)")
        if args.patrol is not None:
            plan = plan_patrol(ts, _start_cell(ts, start, None), _labels(args.patrol), avoid=_labels(args.avoid))
        elif args.formula is not None:
            plan = make_plan(ts, args.formula, start=start)
        elif args.ltl is not None:
            plan = make_plan(ts, ltl=args.ltl, start=start)
        else:
            plan = make_plan(ts, _labels(args.sequence), start=start, planner=args.planner)
        out = Path(args.out) if args.out else Path(args.directory) / "controller"
        files = export_controller(ts, plan, out, langs, cycles=args.cycles, weights=args.weights)
    except PlanningError as exc:
        print(f"error: no plan: {exc}", file=sys.stderr)
        return 1
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1 if str(exc).startswith(EVIDENCE_FAILS) else 2
    what = (f"a prefix and a cycle of {plan.stats['cycle_steps']} steps, repeated "
            + ("forever" if args.cycles is None else f"{args.cycles} times")) if plan.kind in ("patrol", "ltl") else \
        f"{plan.plan.cost} steps, {len(plan.plan.edges)} transitions"
    spec = re.sub(r" x\d+(?=,|$)", "", plan.spec) if plan.kind == "patrol" else plan.spec   # repeats: the export's
    print(f"exported the controller of {spec!r} ({what}) to {out}: " + ", ".join(f.name for f in files))
    return 0


def main(argv=None) -> int:
    """``python -m tubejax COMMAND ...``."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(USAGE)
        return 0 if argv else 2
    if argv[0] == "export-controller":
        return export_main(argv[1:], prog="python -m tubejax export-controller")
    if argv[0] != "verify":
        print(f"error: unknown command {argv[0]!r} (expected: verify, export-controller)", file=sys.stderr)
        return 2
    return verify_main(argv[1:], prog="python -m tubejax verify")


if __name__ == "__main__":
    sys.exit(main())
