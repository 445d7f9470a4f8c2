"""HiGHS's dual simplex may stop at status 'Unknown' on a feasible margin LP: the verdict retries.

Found by the property tests (tests/properties, box3 campaign): with HiGHS 1.16 the default
solve of the LP below ends with model status ``Unknown``, so the pair lost horizon 3 and got
its edge at ``L = 4``, with either solver. The primal simplex and the interior-point method
both give ``t* = 0.0230829994`` (rows per unit of their LP coefficients, as then) and a tube
that passes the float64 check.
"""

import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.model.geometry import Ball, Polytope
from tubejax.lp.evidence.verdict import highs_verdict
from tubejax.lp.declarations.tube_lp import build_tube_lp, tube_violation
from tubejax.model.zshape.kinds import make_z
from tubejax.lp.engines.highs import solve_margin_lp
from tubejax.model.problem import pair_problem
from tubejax.model.system import LinearSystem
from tubejax.model.workspace import box_grid

C, S = 0.8775825618903728, 0.479425538604203


@pytest.fixture(scope="module")
def case():
    A = np.array([[C, S, 0.0], [-S, C, 0.0], [0.0, 0.0, 1.0]])
    B = np.array([[0.875, -0.125, 0.0], [-0.25, 0.625, 1e-07], [0.125, 0.0, 0.625]])
    U = Polytope.box([-0.5, -1.0, -0.5], [1.0, 1.5, 1.0])
    sysm = LinearSystem(A=A, B=B, U=U, W=Ball(3, 0.0))
    d = box_grid([0.0, -2.0, 0.0], [2.0, -0.5, 0.75], [2, 2, 1])
    return d, sysm


def test_unknown_status_is_retried(case):
    d, sysm = case
    # Z as the case was found: the cell's shape at unit largest vertex norm (make_z's 'cell' now
    # scales by a power of two; the state-space margins below do not depend on Z's scale)
    V = d.cells[1].vertices - d.cells[1].vertices.mean(axis=0)
    p = pair_problem(d, sysm, Polytope.from_vertices(V / np.max(np.linalg.norm(V, axis=1))), 1, 3, 3)
    assert np.isclose(highs_verdict(pair_problem(d, sysm, make_z("cell", d.cells[1]), 1, 3, 3)).margin,
                      highs_verdict(p).margin, rtol=0, atol=1e-9)
    # the LP as found (rows per unit of their coefficients, transition files before format 3)
    old = solve_margin_lp(build_tube_lp(p, scaling="coefficients"), {"solver": "ipm"})
    assert old.status == "Optimal" and old.margin == pytest.approx(0.0230829994, abs=1e-9)
    lp = build_tube_lp(p)                                # margins in state-space units
    reference = solve_margin_lp(lp, {"solver": "ipm"})
    assert reference.status == "Optimal" and reference.margin >= old.margin > 0
    v = highs_verdict(p)
    assert v.status == "edge" and abs(v.margin - reference.margin) <= 1e-9
    assert tube_violation(p, v.tube) <= 1e-9


def test_abstraction_keeps_the_minimal_horizon(case):
    d, sysm = case
    ts = build_abstraction(d, sysm, zshape="cell", L_max=4, progress=False)
    assert ts.stats["n_unconfirmed"] == 0
    assert {(e.src, e.dst): e.L for e in ts.edges}[1, 3] == 3
    ts.verify()
