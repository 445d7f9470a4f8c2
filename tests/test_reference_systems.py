"""The abstraction gives the transition systems of the all-pairs algorithm it replaced.

``tests/data/reference_edges.json`` was recorded with commit 1dd90d5 (all pairs, pruning by
set-level reach only; see ``tests/data/make_reference_edges.py``). Candidate pairs, the new
pruning rules and the vectorised obstacle case must change nothing in the edges or their
``L``, with pruning on and off, in 2-D (grid maps, a triangulation, a non-box ``U``, a
sheared ``A``) and 4-D (the double integrator on box grids).
"""

import json
from pathlib import Path

import pytest

from reference_cases import CASES, run_case

REFERENCE = json.loads((Path(__file__).resolve().parent / "data" / "reference_edges.json").read_text())

FAST = ["tiny-pruned", "tiny-unpruned", "corridor-pruned", "corridor-unpruned", "open-pruned", "maze-pruned",
        "corridor-l1-pruned", "open-sheared-pruned", "open-sheared-unpruned", "boxgrid4d-pruned"]
SLOW = ["rooms-pruned", "boxgrid4d-unpruned", "boxgrid4d-3232-pruned", "paper-pdhg-pruned"]


def _edges(ts):
    return [[e.src, e.dst, e.L] for e in ts.edges]


@pytest.mark.parametrize("name", FAST + [pytest.param(n, marks=pytest.mark.slow) for n in SLOW])
def test_same_edges_as_the_all_pairs_algorithm(name):
    ref = REFERENCE["cases"][name]
    assert ref["case"] == json.loads(json.dumps(CASES[name]))      # the recorded case is this one
    ts = run_case(CASES[name])
    assert _edges(ts) == ref["edges"]
    assert ts.stats["n_lps"] <= ref["n_lps"]
    if CASES[name]["pruning"]:
        assert ts.stats["n_lps"] < ref["n_lps"]                     # the new rules prune more


@pytest.mark.parametrize("pruned, unpruned", [("maze-pruned", "maze-unpruned"),
                                              ("boxgrid4d-3232-pruned", "boxgrid4d-3232-unpruned")])
def test_no_edge_lost_against_unpruned_highs(pruned, unpruned):
    """Pruned runs of today's code against the UNPRUNED HiGHS runs (every pair, every L)."""
    ref = REFERENCE["cases"][unpruned]
    assert not ref["case"]["pruning"] and ref["case"]["solver"] == "highs"
    ts = run_case(CASES[pruned])
    assert _edges(ts) == ref["edges"]
    assert ts.stats["n_lps"] < ref["n_lps"] / 2
