"""Command line: ``python -m tubejax verify DIR [--complete] [--stem NAME] [--no-exact]``.

Exit status: 0 verified; 1 something failed verification (each finding on its own line);
2 a usage error.
"""

from __future__ import annotations

import argparse
import sys
from .verify.verifier import verify_directory

__all__ = ["main", "verify_main"]


def _verify_parser(prog: str) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description="Prove a saved transition system from its sources: "
                                "rebuild the problem from the recorded inputs, re-check every edge's "
                                "evidence (float64 and exact), and optionally re-solve every non-edge.")
    p.add_argument("directory", help="the directory holding <stem>.json and <stem>.npz")
    p.add_argument("--stem", default="transitions", help="file stem (default: transitions)")
    p.add_argument("--complete", action="store_true",
                   help="also re-solve every non-edge up to L_max with HiGHS (finds deleted edges)")
    p.add_argument("--no-exact", action="store_true", help="skip re-proving the exact (rational) proofs")
    p.add_argument("--trust-file-data", action="store_true",
                   help="for a file without an inputs record: check it against its own copied data")
    p.add_argument("--quiet", action="store_true", help="print only findings and the verdict")
    return p


def verify_main(argv=None, prog: str = "tubejax-verify") -> int:
    """Run the verifier; returns the exit status."""

    args = _verify_parser(prog).parse_args(argv)
    rep = verify_directory(args.directory, args.stem, complete=args.complete, exact=not args.no_exact,
                           progress=not args.quiet, trust_file_data=args.trust_file_data)
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


def main(argv=None) -> int:
    """``python -m tubejax COMMAND ...``."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: python -m tubejax verify DIR [--complete] [--stem NAME] [--no-exact] [--trust-file-data]")
        return 0 if argv else 2
    if argv[0] != "verify":
        print(f"error: unknown command {argv[0]!r} (expected: verify)", file=sys.stderr)
        return 2
    return verify_main(argv[1:], prog="python -m tubejax verify")


if __name__ == "__main__":
    sys.exit(main())
