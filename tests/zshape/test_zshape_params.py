"""Parametrised families of Z: normalisation, facets, invariants (0 interior, vertex count, pairing)."""

import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tubejax.model.geometry import Polytope
from tubejax.model.zshape.kinds import make_z
from tubejax.model.zshape.params import (ZFamily, ZShapeError, box_corners, family_for, final_z, normalise_theta,
                                            polytope_from_z, repair_theta, theta_from_z, theta_mask, z_facets,
                                            z_from_theta, z_valid)

QUAD = ZFamily("polygon", 2, 4, 4)
TRI = ZFamily("polygon", 2, 3, 3)
CUBE = ZFamily("parallelotope", 3, 8, 6)
SQUARE = Polytope.box([0.0, 0.0], [1.0, 1.0])
KITE = [[-1.0, -1.0], [1.05, -0.98], [0.97, 1.02], [-1.02, 0.97]]


def test_box_is_a_fixed_point_and_facets_match_polytope():
    z = np.asarray(z_from_theta(QUAD, theta_from_z(QUAD, make_z("box", SQUARE))))
    np.testing.assert_array_equal(z, [[-1, -1], [1, -1], [1, 1], [-1, 1]])
    H, h = z_facets(QUAD, z, np)
    P = Polytope.from_vertices(z)
    np.testing.assert_allclose(H, P.H, atol=1e-15)
    np.testing.assert_allclose(h, P.h, atol=1e-15)
    Hj, hj = z_facets(QUAD, jnp.asarray(z))                     # JAX and NumPy: the same formula
    np.testing.assert_allclose(np.asarray(Hj), H, atol=1e-15)
    for kind in ("box", "diamond", "cell", "regular"):
        assert bool(z_valid(QUAD, z_from_theta(QUAD, theta_from_z(QUAD, make_z(kind, SQUARE)))))


def test_parallelotope_corners_facets_and_box():
    assert np.array_equal(box_corners(3), Polytope.box(-np.ones(3), np.ones(3)).vertices)
    M = np.array([[1.0, 0.3, -0.2], [0.0, 0.8, 0.1], [0.0, 0.0, 1.2]])
    z = np.asarray(z_from_theta(CUBE, M))
    assert bool(z_valid(CUBE, z))
    P = polytope_from_z(CUBE, z)                               # canonical order kept on reload
    np.testing.assert_array_equal(P.vertices, z)
    H, h = z_facets(CUBE, z, np)
    assert np.all(z @ H.T <= h + 1e-12)                        # every vertex inside every facet
    assert np.all(np.sum(np.isclose(z @ H.T, h, atol=1e-12), axis=0) == 4)   # 4 vertices per facet
    np.testing.assert_allclose(np.sqrt(np.mean(np.sum(z ** 2, axis=1))), np.sqrt(3))
    np.testing.assert_array_equal(theta_mask(CUBE), np.triu(np.ones((3, 3))))


def test_stored_parallelotope_is_exact():
    """The stored corners are exactly M c_k (rational check): an exact parallelotope for the proofs."""
    from fractions import Fraction

    M = np.array([[1.0, 0.3, -0.2], [0.0, 0.8, 0.1], [0.0, 0.0, 1.2]]) / 3.0
    z = final_z(CUBE, M)
    Mr = theta_from_z(CUBE, z)
    assert np.all(Mr * 2 ** 30 == np.round(Mr * 2 ** 30))          # dyadic entries
    for k, c in enumerate(box_corners(3)):
        for d in range(3):
            assert Fraction(z[k, d]) == sum(Fraction(Mr[d, j]) * int(c[j]) for j in range(3))
    np.testing.assert_allclose(z, np.asarray(z_from_theta(CUBE, M)), atol=1e-8)
    np.testing.assert_array_equal(final_z(QUAD, np.array(KITE)), np.asarray(z_from_theta(QUAD, np.array(KITE))))


def test_lower_triangular_parallelotope_would_reorder_corners():
    M = np.eye(3)
    M[1, 0] = 2.0                                  # y of the corners at z = -1: -3, 1, -1, 3
    z = np.asarray(z_from_theta(CUBE, M))
    assert not bool(z_valid(CUBE, z))
    with pytest.raises(ZShapeError, match="re-ordered|invariant"):
        polytope_from_z(CUBE, z)
    M[1, 0] = 0.3                                  # -1.3, -0.7, 0.7, 1.3: still in order, allowed
    z = np.asarray(z_from_theta(CUBE, M))
    np.testing.assert_array_equal(polytope_from_z(CUBE, z).vertices, z)


@pytest.mark.parametrize("V, why", [
    ([[-1, -1], [1, -1], [-1, 1], [1, 1]], "not convex / clockwise"),
    ([[-1, -1], [1, -1], [1, 1], [0, -1]], "a collinear vertex"),
    ([[-1, -0.5], [1, -1], [1, 1], [-1, 1]], "vertex 2 below vertex 1: the pairing would change"),
    ([[-1, -1], [1, -1], [1, 1], [-1, 1 + 1e-11]], None),
])
def test_polygon_invariants(V, why):
    z = np.asarray(z_from_theta(QUAD, np.array(V, float)))
    if why is None:
        assert bool(z_valid(QUAD, z))
        return
    assert not bool(z_valid(QUAD, z)), why
    with pytest.raises(ZShapeError):
        polytope_from_z(QUAD, z)


def test_order_ties_are_accepted_only_when_exact():
    z = np.array([[-1.0, -1.0], [1.0, -1.0 + 1e-12], [1.0, 1.0], [-1.0, 1.0]])
    assert not bool(z_valid(QUAD, z))                          # rounding to 12 decimals could flip it
    r = np.asarray(repair_theta(QUAD, z))
    assert bool(z_valid(QUAD, r)) and r[1, 1] > r[0, 1]
    with pytest.raises(ZShapeError):
        polytope_from_z(QUAD, np.zeros((3, 2)))                 # wrong vertex count


def test_family_for():
    assert family_for(SQUARE) == QUAD
    assert family_for(Polytope.box(np.zeros(4), np.ones(4))) == ZFamily("parallelotope", 4, 16, 8)
    tet = Polytope.from_vertices([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    with pytest.raises(ZShapeError, match="2\\^3"):
        family_for(tet)
    with pytest.raises(ZShapeError, match="not a parallelotope"):
        theta_from_z(ZFamily("parallelotope", 2, 4, 4), make_z("diamond", SQUARE))


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-0.3, 0.3), min_size=8, max_size=8), st.floats(0.2, 5.0),
       st.lists(st.floats(-3, 3), min_size=2, max_size=2))
def test_normalisation_removes_scale_and_translation(noise, scale, shift):
    th = np.array([[-1.0, -1], [1, -1], [1, 1], [-1, 1]]) + np.reshape(noise, (4, 2))
    z = np.asarray(z_from_theta(QUAD, th))
    z2 = np.asarray(z_from_theta(QUAD, scale * th + np.asarray(shift)))
    np.testing.assert_allclose(z2, z, atol=1e-12)
    np.testing.assert_allclose(z.mean(axis=0), 0, atol=1e-12)
    np.testing.assert_allclose(np.mean(np.sum(z ** 2, axis=1)), 2.0)
    np.testing.assert_allclose(np.asarray(normalise_theta(QUAD, z)), z, atol=1e-12)
    if bool(z_valid(QUAD, z)):                                  # valid => 0 interior and reload-stable
        P = polytope_from_z(QUAD, z)
        assert np.all(P.h > 0) and P.n_vertices == 4


# a learned hexagon whose first two vertices differ in y by 4e-9 (repair_theta's floor): valid in
# float64, a tie in float32
NEAR_TIE = [[0.6923412387180083, -1.1289256048275111], [1.2154772406731047, -0.44995870056243253],
            [1.0073981977326576, 1.0697555221519255], [-0.6933253778371388, 1.4281742001782063],
            [-1.3343399477949969, 0.20988018386617968], [-0.887551351491635, -1.128925600806368]]


def test_the_host_check_is_float64_whatever_jax_precision():
    import subprocess
    import sys
    from pathlib import Path

    from tubejax.model.zshape.params import z_valid_host

    fam = ZFamily("polygon", 2, 6, 6)
    assert z_valid_host(fam, NEAR_TIE) and bool(z_valid(fam, jnp.asarray(NEAR_TIE)))
    assert polytope_from_z(fam, np.array(NEAR_TIE)).n_vertices == 6
    bad = np.array(NEAR_TIE)
    bad[5, 1] = bad[0, 1] + 1e-12                          # inside ORDER_TOL: neither first nor a tie
    assert not z_valid_host(fam, bad) and not bool(z_valid(fam, jnp.asarray(bad)))
    # a process without jax_enable_x64 (as `python -m tubejax verify`) reloads it too
    code = ("import numpy as np; from tubejax.model.zshape.params import ZFamily, polytope_from_z; "
            f"print(polytope_from_z(ZFamily('polygon', 2, 6, 6), np.array({NEAR_TIE!r})).n_vertices)")
    root = Path(__file__).resolve().parents[2]
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root,
                       env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"}, timeout=300)
    assert p.returncode == 0 and p.stdout.strip() == "6", p.stderr
