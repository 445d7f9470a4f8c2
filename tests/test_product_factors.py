"""The factor phase of the product path (tubejax.abstraction.product_factors): translation classes and
twin factors save LPs without changing a verdict.

On a lifted 2-D map (two double-integrator factors, tests below): compared with the plain solve of every
factor LP (``pruning=False``: no class, no pruning; and :func:`solve_factor` group by group), the same
feasible horizons and edge margins, and every non-edge settled by translation is a non-edge of its own
HiGHS LP with the same margin up to rounding.
"""

import numpy as np
import pytest

from tubejax.abstraction.product_factors import same_factor_data, solve_factor, solve_factors
from tubejax.abstraction.translation_classes import TRANSFER_MARGIN, TRANSLATE_PROVENANCE
from tubejax.lp.evidence.verdict import highs_solve_batch
from tubejax.model.geometry import Ball
from tubejax.model.product_structure import product_structure
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.system_kinds import double_integrator_lookahead
from tubejax.model.workspace import box_grid
from tubejax.model.workspace.lookahead import lift_lookahead
from tubejax.model.zshape.kinds import cross_sections

L_MAX = 3


def _structure(upper, divisions):
    """A free map ``[0, upper]`` in unit cells, lifted by ``divisions`` look-ahead slabs per axis."""
    d = lift_lookahead(box_grid([0, 0], upper, upper), divisions)
    A, B = double_integrator_lookahead(2, 0.5, 2.0)
    sysm = LinearSystem(A=A.astype(float), B=B.astype(float), U=box_input_set(1.0, 2), W=Ball(4, 0.01))
    return product_structure(d, sysm, cross_sections(d, "cell", 1.0))


@pytest.fixture(scope="module")
def square():
    st = _structure([6, 6], [3, 3])                  # look-ahead slabs 2 wide: cells translate by 2
    return st, solve_factor(st.factors[0], 0, L_MAX, pruning=False)


def test_translation_classes_change_no_verdict(square):
    st, plain = square
    t = solve_factor(st.factors[0], 0, L_MAX)
    np.testing.assert_array_equal(t.feasible, plain.feasible)
    moved = [k for k, v in t.verdicts.items()
             if v.provenance == TRANSLATE_PROVENANCE and not (k[0] == 1 and k[2] == k[3])]    # self-pairs: once
    assert len(moved) == t.n_translated > 0 and t.n_lps + t.n_translated < plain.n_lps
    own = dict(zip(moved, highs_solve_batch([t.problem(*k) for k in moved])))
    for key, v in t.verdicts.items():
        assert v.status == plain.verdicts[key].status
        if key in own:
            assert v.status == own[key].status == "infeasible"
            assert v.margin < -TRANSFER_MARGIN and abs(v.margin - own[key].margin) <= 1e-9
        if v.status == "edge":
            assert v.margin == plain.verdicts[key].margin
    solved = solve_factor(st.factors[0], 0, L_MAX, by_class=False)      # a verifier's re-solve: every LP kept
    assert solved.n_translated == 0 and solved.n_lps == t.n_lps + t.n_translated
    np.testing.assert_array_equal(solved.feasible, t.feasible)


def test_twin_factors_are_solved_once(square):
    st, plain = square
    assert same_factor_data(st.factors[0], st.factors[1])
    tables = solve_factors(st.factors, L_MAX, pruning=False)
    assert tables[0].n_lps == plain.n_lps and tables[1].n_lps == 0 and tables[1].factor is st.factors[1]
    for t in tables:
        np.testing.assert_array_equal(t.feasible, plain.feasible)
        np.testing.assert_array_equal(t.margin, plain.margin)
        assert {k: v.status for k, v in t.verdicts.items()} == {k: v.status for k, v in plain.verdicts.items()}


def test_factors_that_differ_are_each_solved():
    st = _structure([3, 2], [2, 2])                  # 3 columns, 2 rows: the factor cells differ
    assert not same_factor_data(st.factors[0], st.factors[1])
    tables = solve_factors(st.factors, 2)
    assert all(t.n_lps > 0 for t in tables)
