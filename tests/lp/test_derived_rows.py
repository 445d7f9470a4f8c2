"""Rows derived from the open-loop LP's declaration, against a hand derivation on a 2-D system.

Two consumers read the open-loop LP's rows off its row families instead of writing them again:
the explicit coefficients of the open-loop operator (the PDHG setup's diagonal scaling,
``OpenLoopData.CS`` / ``CT``) and the abstraction's vertex LPs (``vertex_screen.ShapeRows``).
Here both are held to the rows written out by hand for the double integrator
``A = [[1, 1/2], [0, 1]]``, ``B = [0, 1/2]^T``, whose powers are ``A^k B = [k/4, 1/2]^T``: a row
missing, moved or mis-scaled fails.
"""

import numpy as np
import pytest

from tubejax.abstraction.vertex_screen import ShapeRows, StepTables
from tubejax.lp.declarations.openloop_operator import openloop_coef_data
from tubejax.lp.declarations.openloop_families import (OPENLOOP_FAMILIES, PlanTerms, SetRows, plan_identity,
                                                       step_rows)
from tubejax.lp.declarations.openloop_operator_data import build_openloop_data
from tubejax.lp.declarations.row_families import dense_rows
from tubejax.model.geometry import Ball, Polytope
from tubejax.model.problem import TubeProblem
from tubejax.model.system import LinearSystem, box_input_set

A = np.array([[1.0, 0.5], [0.0, 1.0]])
B = np.array([[0.0], [0.5]])


def AkB(k: int) -> np.ndarray:
    """``A^k B``, by hand."""
    return np.array([k / 4, 0.5])


def Ak(k: int) -> np.ndarray:
    """``A^k``, by hand."""
    return np.array([[1.0, k / 2], [0.0, 1.0]])


def hand_rows(H: np.ndarray, step: int, L: int) -> np.ndarray:
    """The coefficients of ``u(0 .. L-1)`` in the rows ``H x(step)``, shape ``(f, L)``."""
    return np.array([[H[f] @ AkB(step - 1 - t) if t < step else 0.0 for t in range(L)] for f in range(len(H))])


# ----------------------------------------------------------------------------- open-loop coefficients
SYSTEM = LinearSystem(A=A, B=B, U=box_input_set(1.0, 1), W=Ball(2, 0.05))


def _problem(L: int, target_hi: float) -> TubeProblem:
    sysm = SYSTEM
    Pi = Polytope.box([0.0, -0.5], [1.0, 0.5])
    Pj = Polytope.from_vertices(np.array([[1.0, -0.5], [target_hi, 0.0], [1.0, 0.5]]))     # a triangle
    S = Polytope.box([-1.0, -1.0], [3.0, 1.0])
    return TubeProblem(sysm, Pi, Pj, S, Polytope.box([-1.0, -1.0], [1.0, 1.0]), L, S.bounding_box())


@pytest.mark.parametrize("radius", [False, True])
def test_openloop_coefficients_equal_the_hand_derived_rows(radius):
    """``CS[l-1, f, t, 0, b] = H_S[f] A^{l-1-t} B / ||H_S[f]||`` for ``t < l``, ``CT`` the same with the
    target's facets at the instance's own horizon; zero on padded steps, facets and inputs."""
    probs = [_problem(3, 2.0), _problem(2, 2.5)]                    # horizons 3 and 2, padded to 4
    shape, data = build_openloop_data(probs, L_pad=4, f_s=6, f_t=5, W0=Ball(2, 1.0) if radius else None)
    coef = openloop_coef_data(shape, data)
    assert coef.CS.shape == (3, 6, 4, 1, 2) and coef.CT.shape == (5, 4, 1, 2)
    for b, p in enumerate(probs):
        HS = p.safe.H / np.linalg.norm(p.safe.H, axis=1)[:, None]
        HT = p.target.H / np.linalg.norm(p.target.H, axis=1)[:, None]
        want = np.zeros((3, 6, 4))
        for ell in range(1, p.L):
            want[ell - 1, :len(HS)] = hand_rows(HS, ell, 4)
        np.testing.assert_allclose(coef.CS[..., 0, b], want, rtol=0, atol=1e-15)
        wantT = np.zeros((5, 4))
        wantT[:len(HT)] = hand_rows(HT, p.L, 4)
        np.testing.assert_allclose(coef.CT[..., 0, b], wantT, rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match="CS, CT"):
        openloop_coef_data(shape, data.lean())


# ----------------------------------------------------------------------------- vertex-LP rows
HS = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]])
Hj = np.array([[1.0, 1.0], [-1.0, 0.0], [0.0, -1.0]]) / np.array([[np.sqrt(2)], [1.0], [1.0]])


def test_step_rows_equal_the_hand_derived_rows():
    C, M = step_rows(Hj, A, B, 4)
    assert C.shape == (4, 3, 4, 1) and M.shape == (4, 3, 2)
    for ell in range(1, 5):
        np.testing.assert_allclose(C[ell - 1, :, :, 0], hand_rows(Hj, ell, 4), rtol=0, atol=1e-15)
        np.testing.assert_allclose(M[ell - 1], Hj @ Ak(ell), rtol=0, atol=1e-15)


@pytest.mark.parametrize("L", [2, 3, 5])
def test_vertex_lp_rows_equal_the_hand_derived_rows(L):
    """A vertex LP of horizon ``L``: the ``S`` rows of steps ``1 .. L-1`` then the ``P_j`` rows of step
    ``L`` on ``u(0 .. L-1)``; its right-hand side's vertex part ``H A^l``; the reach of each step."""
    ulo, uhi = np.array([-2.0]), np.array([1.0])
    rows = ShapeRows(HS, Hj, StepTables(A, B, 5, ulo, uhi))
    want = np.concatenate([hand_rows(HS, ell, L) for ell in range(1, L)] + [hand_rows(Hj, L, L)])
    hz = rows.at(L)
    assert hz.G.shape == want.shape == ((L - 1) * 4 + 3, L)
    np.testing.assert_allclose(hz.G, want, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(hz.lo, np.full(L, -2.0))
    for ell in range(1, 6):
        np.testing.assert_allclose(rows.MS[ell], HS @ Ak(ell), rtol=0, atol=1e-15)
        np.testing.assert_allclose(rows.Mj[ell], Hj @ Ak(ell), rtol=0, atol=1e-15)
        reach = sum(2.0 * np.abs(HS @ AkB(t)) for t in range(ell))
        np.testing.assert_allclose(rows.reachS[ell - 1], reach, rtol=1e-15)


def test_vertex_lp_rows_are_the_openloop_lp_rows_of_one_vertex():
    """The vertex LP is the open-loop LP (:data:`OPENLOOP_FAMILIES`) of one vertex over the shrunk
    sets with no disturbance tightening: the same rows, in the same order."""
    L = 4
    sets = {"safe": SetRows(HS, np.zeros(4), np.ones(4)), "target": SetRows(Hj, np.zeros(3), np.ones(3)),
            "input": SetRows(np.array([[1.0], [-1.0]]), np.ones(2), np.ones(2))}
    d = PlanTerms(L, np.zeros((1, 2)), A, B, sets, {r: np.zeros((L + 1, len(sets[r].H))) for r in ("safe", "target")},
                  np.concatenate, frozenset(sets))
    G, _, layout = dense_rows(d, 1, "margin", True, OPENLOOP_FAMILIES, plan_identity)
    assert layout.names == ("safe", "target")
    np.testing.assert_array_equal(ShapeRows(HS, Hj, StepTables(A, B, 6, np.array([-1.0]), np.array([1.0]))).at(L).G, G)
