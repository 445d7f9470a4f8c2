"""The numbers of docs/math/worked-example.md and docs/math/paper.md are the code's.

``scripts/paper_comparison.py`` prints them; these tests recompute them with its functions and
compare them with the tables of the pages, so a change of the code that changes them fails here
until the pages are regenerated. The LP's optimal margins are also held to the hand derivation
of the worked example (the trailing-face chain ``t* = (0.3 L − 2) / (L + 1)``).
"""

import importlib.util
import re
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
WORKED = ROOT / "docs" / "math" / "worked-example.md"
PAPER = ROOT / "docs" / "math" / "paper.md"


def _script():
    spec = importlib.util.spec_from_file_location("paper_comparison", ROOT / "scripts" / "paper_comparison.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _table(text: str, header: str) -> list[list[str]]:
    """The rows (cells stripped) of the Markdown table whose header row starts with ``header``."""
    lines = text.splitlines()
    start = next(k for k, line in enumerate(lines) if line.startswith(header))
    rows = []
    for line in lines[start + 2:]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip("|").split("|")])
    return rows


@pytest.fixture(scope="module")
def pair():
    return _script().worked_pair()


def test_worked_pair_sizes_and_margins_match_the_page(pair):
    rows = _table(WORKED.read_text(encoding="utf-8"), "| L | columns |")
    assert len(rows) == len(pair["sizes"]) == 10
    for row, (L, cols, n_rows, fam, t) in zip(rows, pair["sizes"]):
        assert row[0] == str(L) and row[1] == str(cols)
        assert row[2] == f"{n_rows} ({fam['safe']} / {fam['target']} / {fam['dynamics']})"
        assert float(row[3]) == pytest.approx(t, abs=5e-6)
        # the page's size formulas (11 L + 1 columns, 20 L margin rows) and the general count
        assert cols == 11 * L + 1 and n_rows == 20 * L
        if L >= 2:                                   # the trailing-face chain binds (t = 1 binds nothing)
            assert t == pytest.approx((0.3 * L - 2) / (L + 1), abs=1e-9)


def test_worked_pair_least_L_and_tube_match_the_page(pair):
    text = WORKED.read_text(encoding="utf-8")
    assert pair["L_min"] == 7 and "**`L = 7`**" in text
    assert Fraction(pair["t_min"]).limit_denominator(1000) == Fraction(1, 80) and "`t* = 0.0125 = 1/80`" in text
    assert pair["violation"] <= 1e-9
    tube = pair["tube"]
    rows = _table(text, "| ℓ | p_ℓ |")
    assert len(rows) == len(tube.eps) == 7
    for ell, row in enumerate(rows):
        px, py = (float(v) for v in row[1].strip("()").split(","))
        assert (px, py) == pytest.approx(tuple(tube.p[ell]), abs=5e-6)
        assert float(row[2]) == pytest.approx(tube.eps[ell], abs=5e-6)
        assert float(row[3]) == pytest.approx(pair["trailing"][ell], abs=5e-6)
    # the left faces are the chain's, tight at every step: a_l = (0.3 - 1/80) l
    np.testing.assert_allclose(pair["trailing"], (0.3 - 1 / 80) * np.arange(1, 8), atol=1e-9)
    for line, ells in (("ℓ = 0:", [0]), ("ℓ = 1:", [1]), ("ℓ = 2 … 6:", range(2, 7))):
        shown = re.search(re.escape(line) + r"\s+(.*)", text).group(1).replace("−", "-")
        pairs = [tuple(map(float, m)) for m in re.findall(r"\(([-\d.]+), ([-\d.]+)\)", shown)]
        for ell in ells:
            np.testing.assert_allclose(np.array(pairs), tube.u[ell], atol=5e-6)


def test_worked_pair_readings(pair):
    text = WORKED.read_text(encoding="utf-8")
    assert pair["obstacle_case"] is False
    assert pair["closed_test"] is None                    # "no L <= 10 works" in the obstacle case
    assert pair["one_norm_U"] == 20 and "the pair needs `L = 20`" in text


@pytest.mark.slow
def test_offsets_match_the_page():
    by = {(off, u, w): L for off, u, w, L in _script().offsets_table()}
    for (off, u, w), L in by.items():                   # the norm of W never matters on a grid with a box Z
        assert L == by[(off, u, "ball")]
    box = {off: by[(off, "box", "ball")] for off in _script().OFFSETS}
    assert [box[(1, 0)], box[(2, 0)], box[(3, 0)]] == [4, 7, 10]
    assert [box[(1, 1)], box[(2, 1)], box[(2, 2)]] == [4, 7, 7]
    assert 8 not in box.values()


@pytest.mark.slow
def test_counts_match_the_paper_page():
    rows = _table(PAPER.read_text(encoding="utf-8"), "| reading |")
    computed = _script().counts()
    assert len(rows) == len(computed)
    for row, (name, n, e, L) in zip(rows, computed):
        assert row == [name, str(n), str(e), str(L)]
