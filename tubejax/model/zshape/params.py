"""Parametrisations of a learned cross-section ``Z``: vertices, facets, invariants.

Each family is a smooth map from ``theta`` to ``Z``'s vertices (canonical order, so vertex ``k``
stays paired with the cell's vertex ``k``) and its unit facets ``H z <= h``: ``polygon`` (2-D,
``theta (n_v, 2)`` the vertices counter-clockwise) and ``parallelotope`` (``n >= 3``,
``Z = M [-1, 1]^n`` with ``M`` upper triangular with a positive diagonal, which keeps the box's corner
order; :func:`theta_mask`). Problem 2's feasibility does not change when ``Z`` is translated or
scaled, so the maps centre the vertices and scale them to RMS radius ``sqrt(n)``.
:func:`z_valid` (in JAX) and :func:`polytope_from_z` (exactly) check the invariants: every vertex
extreme, 0 interior, the canonical order the parameter order (ties exact, else apart by
:data:`ORDER_TOL`).
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ...errors import ZShapeError
from ..geometry import Polytope

__all__ = ["ZFamily", "ZShapeError", "family_for", "family_of", "normalise_theta", "repair_theta", "z_from_theta",
           "z_from_theta_host", "normalise_theta_host", "z_valid_host", "z_facets", "z_valid", "theta_from_z",
           "polytope_from_z", "box_corners", "theta_mask", "final_z", "DYADIC_STEP", "ORDER_TOL", "CONVEX_TOL"]

#: A coordinate difference that decides the canonical order must exceed this (or be exactly 0).
ORDER_TOL = 1e-9
#: Smallest turn (cross product of consecutive unit edges) and facet offset ``h`` accepted.
CONVEX_TOL = 1e-6


class ZFamily(NamedTuple):
    """A parametrised family of cross-sections.

    Attributes
    ----------
    kind : {'polygon', 'parallelotope'}
    n : int            state dimension
    n_vertices : int   ``n_v``
    n_facets : int     ``n_v`` (polygon) or ``2 n`` (parallelotope)
    """

    kind: str
    n: int
    n_vertices: int
    n_facets: int

    @property
    def theta_shape(self) -> tuple:
        return (self.n_vertices, 2) if self.kind == "polygon" else (self.n, self.n)


def family_for(cell: Polytope) -> ZFamily:
    """The family that can pair with ``cell``: polygons in 2-D, parallelotopes for ``2^n``-vertex cells
    (a ``ZShapeError`` for any other cell)."""
    return family_of(cell.dim, cell.n_vertices)


def family_of(n: int, nv: int) -> ZFamily:
    """:func:`family_for` a cell of ``nv`` vertices in ``R^n``."""
    if n == 2:
        return ZFamily("polygon", 2, nv, nv)
    if nv == 2 ** n:
        return ZFamily("parallelotope", n, nv, 2 * n)
    raise ZShapeError(f"a learned Z needs a 2-D cell or a {n}-D cell with 2^{n} = {2 ** n} vertices, "
                      f"got a cell with {nv} vertices")


def theta_mask(family: ZFamily) -> np.ndarray:
    """1 where a parameter is free, 0 where it stays 0 (the lower part of a parallelotope's ``M``)."""
    if family.kind == "polygon":
        return np.ones(family.theta_shape)
    return np.triu(np.ones(family.theta_shape))


def box_corners(n: int) -> np.ndarray:
    """Corners of ``[-1, 1]^n`` in canonical order (first coordinate fastest), shape ``(2^n, n)``."""
    return np.array([c[::-1] for c in itertools.product((-1.0, 1.0), repeat=n)])


def _normalise(V):
    """Centre on the vertex mean, scale to RMS radius ``sqrt(n)``; ``V`` of shape ``(n_v, n)``."""
    W = V - jnp.mean(V, axis=0)
    rms = jnp.sqrt(jnp.mean(jnp.sum(W * W, axis=1)))
    return W * (jnp.sqrt(V.shape[1]) / rms)


def z_from_theta(family: ZFamily, theta):
    """Vertices of ``Z(theta)``, shape ``(n_v, n)`` (normalised; see the module docstring)."""
    theta = jnp.asarray(theta)
    if family.kind == "polygon":
        return _normalise(theta)
    M = normalise_theta(family, theta)                      # RMS of M c_k is |M|_F
    return jnp.asarray(box_corners(family.n)) @ M.T


#: A final parallelotope's ``M`` is rounded to multiples of this (a power of two), so that its
#: corners ``M c_k`` (sums of ``±M_ij``) are exact in float64 and the stored vertices form an exact
#: parallelotope: the rational proofs (:mod:`tubejax.lp.evidence`) rebuild ``Z``'s facets from them.
DYADIC_STEP = 2.0 ** -30


def final_z(family: ZFamily, theta) -> np.ndarray:
    """The vertices to store for ``theta`` (float64, ``(n_v, n)``): :func:`z_from_theta`, with a
    parallelotope's normalised ``M`` rounded to :data:`DYADIC_STEP` first (see there)."""
    if family.kind == "polygon":
        return np.asarray(z_from_theta_host(family, theta), np.float64)
    M = np.asarray(normalise_theta_host(family, theta), np.float64)
    M = np.round(M / DYADIC_STEP) * DYADIC_STEP
    return box_corners(family.n) @ M.T


def _parallelotope_matrix(family: ZFamily, z, xp=jnp):
    """``M`` with ``z = corners @ M.T``: column ``d`` is half of ``z`` at corner ``2 e_d - 1`` minus ``z_0``."""
    return xp.stack([z[1 << d] - z[0] for d in range(family.n)], axis=1) / 2.0   # 1 << d: corner +e_d


def normalise_theta(family: ZFamily, theta):
    """The normalised parameters of ``Z(theta)`` (a projection: ``Z`` is unchanged)."""
    theta = jnp.asarray(theta)
    if family.kind == "polygon":
        return _normalise(theta)
    return theta * (jnp.sqrt(family.n) / jnp.sqrt(jnp.sum(theta * theta)))


def repair_theta(family: ZFamily, theta):
    """Move parameters back onto the side of the canonical-order constraint they left (a projection):
    a polygon's vertices ``k >= 2`` get ``y_k >= y_1 + 4 ORDER_TOL`` (an optimiser slides along the
    constraint), then normalise. Convexity is not repaired (:func:`z_valid` still decides)."""
    theta = jnp.asarray(theta)
    if family.kind == "polygon":
        y = theta[:, 1]
        scale = jnp.sqrt(jnp.mean(jnp.sum((theta - jnp.mean(theta, 0)) ** 2, axis=1)) / family.n)
        floor = y[0] + 4 * ORDER_TOL * scale
        y = jnp.concatenate([y[:1], jnp.maximum(y[1:], floor)])
        theta = theta.at[:, 1].set(y)
    return normalise_theta(family, theta)


def z_facets(family: ZFamily, z, xp=jnp):
    """Unit facets ``H (n_f, n)``, ``h (n_f,)`` of ``Z`` with vertices ``z (n_v, n)``, in ``xp`` =
    ``jax.numpy`` (differentiable) or ``numpy`` (the host copy of the same formula)."""
    if family.kind == "polygon":
        e = xp.roll(z, -1, axis=0) - z
        N = xp.stack([e[:, 1], -e[:, 0]], axis=1)
        H = N / xp.linalg.norm(N, axis=1, keepdims=True)
        return H, xp.sum(H * z, axis=1)
    M = _parallelotope_matrix(family, z, xp)
    R = xp.linalg.inv(M)
    nr = xp.linalg.norm(R, axis=1)
    Rn = R / nr[:, None]
    return xp.concatenate([-Rn, Rn], axis=0), xp.concatenate([1.0 / nr, 1.0 / nr])


def _order_ok(d, xp=jnp):
    """Whether ``d = b - a`` (``(..., n)``) puts ``b`` after ``a`` in the canonical order (last
    coordinate most significant): the most significant nonzero entry exceeds ORDER_TOL and is the
    only one that is not exactly 0 or clearly decided."""
    n = d.shape[-1]
    nz = d != 0
    idx = xp.arange(n)
    last = xp.max(xp.where(nz, idx, -1), axis=-1)                         # most significant nonzero
    lead = xp.take_along_axis(d, xp.maximum(last, 0)[..., None], axis=-1)[..., 0]
    return (last >= 0) & (lead > ORDER_TOL)


def z_valid(family: ZFamily, z, xp=jnp):
    """Whether ``Z`` with vertices ``z`` (``(n_v, n)``) keeps every invariant (a JAX bool; with
    ``xp=numpy`` a numpy bool computed in float64, whatever JAX's precision setting).

    Polygon: each turn of consecutive unit edges above :data:`CONVEX_TOL`, ``h > CONVEX_TOL``, ``z_1``
    canonically first. Parallelotope: ``det M > 0`` well away from 0, 0 interior, consecutive
    vertices in canonical order.
    """
    z = xp.asarray(z, dtype=np.float64) if xp is np else jnp.asarray(z)
    with np.errstate(all="ignore"):
        H, h = z_facets(family, z, xp)
        ok = xp.all(xp.isfinite(z)) & xp.all(h > CONVEX_TOL)
        if family.kind == "polygon":
            e = xp.roll(z, -1, axis=0) - z
            u = e / xp.linalg.norm(e, axis=1, keepdims=True)
            turn = u[:, 0] * xp.roll(u[:, 1], -1) - u[:, 1] * xp.roll(u[:, 0], -1)
            dy = z[1:, 1] - z[0, 1]
            dx = z[1:, 0] - z[0, 0]
            first = xp.all((dy > ORDER_TOL) | ((dy == 0) & (dx > ORDER_TOL)))
            return ok & xp.all(turn > CONVEX_TOL) & first
        M = _parallelotope_matrix(family, z, xp)
        s = xp.linalg.svd(M, compute_uv=False)
        return ok & (xp.linalg.det(M) > 0) & (s[-1] > CONVEX_TOL * s[0]) & xp.all(_order_ok(z[1:] - z[:-1], xp))


def z_valid_host(family: ZFamily, z) -> bool:
    """:func:`z_valid` in numpy float64 (no compiling; the same answer with or without JAX's x64)."""
    try:
        return bool(z_valid(family, z, np))
    except np.linalg.LinAlgError:                 # a singular parallelotope matrix
        return False


def normalise_theta_host(family: ZFamily, theta) -> np.ndarray:
    """:func:`normalise_theta` in numpy (float64, no compiling; correctly rounded divisions, so a
    normalised box stays exactly the box, which a compiled reciprocal would not)."""
    theta = np.asarray(theta, dtype=np.float64)
    if family.kind == "polygon":
        W = theta - theta.mean(axis=0)
        return W * (np.sqrt(theta.shape[1]) / np.sqrt(np.mean(np.sum(W * W, axis=1))))
    return theta * (np.sqrt(family.n) / np.sqrt(np.sum(theta * theta)))


def z_from_theta_host(family: ZFamily, theta) -> np.ndarray:
    """:func:`z_from_theta` in numpy (see :func:`normalise_theta_host`), shape ``(n_v, n)``."""
    M = normalise_theta_host(family, theta)
    return M if family.kind == "polygon" else box_corners(family.n) @ M.T


def theta_from_z(family: ZFamily, Z) -> np.ndarray:
    """Parameters (``family.theta_shape``) whose ``Z`` is ``Z`` (a ``Polytope`` or its vertices
    ``(n_v, n)``) normalised; a ``ZShapeError`` when ``Z`` is not of the family."""
    V = np.asarray(getattr(Z, "vertices", Z), float)
    if V.shape != (family.n_vertices, family.n):
        raise ZShapeError(f"Z has {V.shape[0]} vertices in R^{V.shape[1]}, the family needs "
                          f"{family.n_vertices} in R^{family.n}")
    if family.kind == "polygon":
        return V.copy()
    V = V - V.mean(axis=0)
    M = _parallelotope_matrix(family, V, np)
    if not np.allclose(box_corners(family.n) @ M.T, V, atol=1e-9 * np.abs(V).max()):
        raise ZShapeError("Z is not a parallelotope M [-1, 1]^n with its corners in canonical order")
    return M


def polytope_from_z(family: ZFamily, z) -> Polytope:
    """The :class:`Polytope` of learned vertices ``z (n_v, n)``, checked exactly on the host: a
    ``ZShapeError`` when :func:`z_valid` fails or a reload would re-order them (the pairing changes)."""
    z = np.asarray(z, dtype=np.float64)
    if z.shape != (family.n_vertices, family.n) or not np.all(np.isfinite(z)):
        raise ZShapeError(f"a learned Z needs {family.n_vertices} finite vertices in R^{family.n}, "
                          f"got an array of shape {z.shape}")
    if family.kind == "parallelotope":
        theta_from_z(family, z)                       # raises unless z = M corners
    if not z_valid_host(family, z):
        raise ZShapeError(f"the learned Z {z.tolist()} breaks an invariant (convex position, 0 interior, "
                          "canonical order)")
    P = Polytope.from_vertices(z)
    if not np.array_equal(P.vertices, z):
        raise ZShapeError(f"the learned Z {z.tolist()} would be re-ordered on reload (pairing changes)")
    return P
