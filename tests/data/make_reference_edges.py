"""Record the reference transition systems of tests/reference_cases.py.

Run with the reference implementation (the all-pairs algorithm of commit 1dd90d5) on the path::

    git clone <repo> /tmp/ref && git -C /tmp/ref checkout 1dd90d5
    PYTHONPATH=/tmp/ref python tests/data/make_reference_edges.py [CASE ...]

It writes (merges into) tests/data/reference_edges.json: per case, the edges ``[src, dst, L]``,
the number of LPs solved and the code's commit.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from reference_cases import CASES, run_case  # noqa: E402


def main(names):
    import tubejax

    src = Path(tubejax.__file__).resolve().parents[1]
    commit = subprocess.run(["git", "-C", str(src), "rev-parse", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    out = HERE / "reference_edges.json"
    data = json.loads(out.read_text()) if out.exists() else {"cases": {}}
    data["commit"] = commit
    for name in names or CASES:
        t0 = time.perf_counter()
        ts = run_case(CASES[name])
        data["cases"][name] = {"case": CASES[name], "n_lps": ts.stats["n_lps"],
                               "edges": [[e.src, e.dst, e.L] for e in ts.edges]}
        print(f"{name}: {ts.n_cells} cells, {ts.n_edges} edges, {ts.stats['n_lps']} LPs, "
              f"{time.perf_counter() - t0:.1f} s", flush=True)
        out.write_text(json.dumps(data, indent=None, separators=(",", ":")) + "\n")


if __name__ == "__main__":
    main(sys.argv[1:])
