"""experiments/product_family_check.py: the product path's edges and L against one joint LP of the
product family per pair (SciPy's HiGHS), on a small lifted building; and that a wrong L is caught."""

import dataclasses
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "experiments"))

import product_family_check as pfc  # noqa: E402

from tubejax.abstraction.product_abstraction import JOINT  # noqa: E402

MAP = str(ROOT / "conf" / "workspace" / "maps" / "building3d_tiny.txt")


def test_sampled_pairs_have_the_systems_least_L():
    r = pfc.run(MAP, [3, 3, 3], L_max=4, n_edges=6, n_non_edges=6)
    assert r["cells"] >= 200 and r["edges"] > 0
    assert r["checked"] == 12 and r["edges_checked"] == 6
    assert r["mismatches"] == [] and r["close"] == 0
    assert pfc.row(r).startswith("| building3d_tiny | 3x3x3 | 756 |")


def test_the_sample_is_factor_edges_then_near_non_edges_and_a_wrong_L_is_caught(monkeypatch):
    built = {}
    real = pfc.build_product_abstraction

    def later(*a, **k):                                 # every edge claimed one horizon later than it is
        ps = built["ps"] = real(*a, **k)
        return dataclasses.replace(ps, L=ps.L + 1)

    monkeypatch.setattr(pfc, "build_product_abstraction", later)
    r = pfc.run(MAP, [3, 3, 3], L_max=4, n_edges=3, n_non_edges=0)
    assert len(r["mismatches"]) == 3
    assert all(got == claimed - 1 for _, _, got, claimed in r["mismatches"])
    ps = built["ps"]
    pairs = pfc.sample_pairs(ps, 5, 5)
    have = {(int(i), int(j)): int(v) for i, j, v in zip(ps.src, ps.dst, ps.variant)}
    assert all(p in have and have[p] != JOINT for p in pairs[:5])
    assert all(p not in have and p[0] != p[1] for p in pairs[5:])
