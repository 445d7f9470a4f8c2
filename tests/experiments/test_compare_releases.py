"""experiments/compare_releases.py: the verdict on two systems and the side-by-side ratios (no runs)."""

import hashlib
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "experiments"))

import compare_releases as cr  # noqa: E402


def _system(tmp_path, name, edges):
    return cr._edge_file(edges, tmp_path / name)


def test_same_edges_in_any_order_are_identical_and_a_changed_L_is_not(tmp_path):
    a = _system(tmp_path, "a.txt", [(0, 1, 2), (1, 0, 3)])
    b = _system(tmp_path, "b.txt", [(1, 0, 3), (0, 1, 2)])
    c = _system(tmp_path, "c.txt", [(0, 1, 2), (1, 0, 4)])
    assert (tmp_path / "a.txt").read_text() == "0 1 2\n1 0 3\n"
    assert a["sha256"] == hashlib.sha256(b"0 1 2\n1 0 3\n").hexdigest()
    v = cr.compare_systems({"m": a, "n": a}, {"m": b, "n": c})
    assert v["m"]["identical"] and not v["n"]["identical"]
    assert (v["n"]["only_base"], v["n"]["only_head"]) == (1, 1)
    assert not cr.compare_systems({"m": a}, {})["m"]["identical"]


def test_ratio_is_the_median_of_the_rounds_ratios_not_of_the_medians():
    rounds = [{"base": {"phases": {"p": b}}, "head": {"phases": {"p": h}}}
              for b, h in ((1.0, 1.2), (10.0, 9.0), (2.0, 2.0))]
    (row,) = cr.summarise(rounds, 0.10)
    assert row["base"] == 2.0 and row["head"] == 2.0
    assert row["ratio"] == 1.0                          # ratios 1.2, 0.9, 1.0
    assert not row["over"]
    (row,) = cr.summarise(rounds[:1], 0.10)
    assert row["over"]
