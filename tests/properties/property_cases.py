"""Hypothesis strategies for the property tests: random small systems and decompositions.

Everything here is drawn by hypothesis (no hidden NumPy randomness), so a failing case
shrinks to a readable one and a run is reproducible from hypothesis's seed.

Systems (``x+ = A x + B u + w``, ``n`` in 1..3):

* ``A``: identity, a scaled identity, a rotation (2-D, 3-D; a negative scalar in 1-D),
  a shear, an unstable diagonal or rotation, or a general matrix (any, possibly singular);
* ``B``: ``b I`` or ``b I`` plus a random perturbation (``m = n``);
* ``U``: a box (possibly off-centre) or, for ``m >= 2``, a non-box polytope with 0 inside
  (a 1-norm ball or a random hull around a cross-polytope);
* ``W``: a 2-norm ball (radius 0 allowed), a box containing 0, or a random polytope
  around 0.

Decompositions:

* box grids (:func:`tubejax.model.workspace.box_grid`) in 1-D, 2-D and 3-D, with random cell
  widths and random obstacle boxes (aligned with the grid or not);
* triangulations of a random star-shaped polygon workspace with an optional obstacle
  (:func:`tubejax.model.workspace.parse_polygon_workspace`), or a fan of triangles built
  directly into a :class:`~tubejax.model.workspace.CellDecomposition`.

The campaign size: ``TUBEJAX_PROPERTY_EXAMPLES=500`` runs 500 examples per property test
instead of the CI numbers (still derandomized: the first examples are CI's);
``TUBEJAX_PROPERTY_SEED=<int>`` draws a different (reproducible) stream instead.
"""

from __future__ import annotations

import os
from typing import NamedTuple

import numpy as np
import shapely
from hypothesis import HealthCheck, assume, event, seed, settings
from hypothesis import strategies as st

from tubejax.model.geometry import Ball, Polytope
from tubejax.lp.evidence.verdict import VERIFY_TOL
from tubejax.model.system import LinearSystem, one_norm_input_set
from tubejax.model.workspace import CellDecomposition, box_grid, parse_polygon_workspace

__all__ = ["Case", "case_strategy", "check_edge", "decomposition", "linear_system", "note_case",
           "property_settings", "CAMPAIGN_EXAMPLES"]

def _env_int(name: str, minimum: int) -> int | None:
    """The integer in environment variable ``name`` (``None`` when unset or empty)."""
    text = os.environ.get(name, "").strip()
    if not text:
        return None
    try:
        value = int(text)
    except ValueError:
        raise ValueError(f"environment variable {name}={text!r}: expected an integer >= {minimum}") from None
    if value < minimum:
        raise ValueError(f"environment variable {name}={value}: expected an integer >= {minimum}")
    return value


#: Examples per property test in a campaign (0: the CI numbers of each test).
CAMPAIGN_EXAMPLES = _env_int("TUBEJAX_PROPERTY_EXAMPLES", 1) or 0
_CAMPAIGN_SEED = _env_int("TUBEJAX_PROPERTY_SEED", 0)


def property_settings(ci_examples: int):
    """``@settings`` of a property test: ``ci_examples`` examples, derandomized, no deadline
    (or :data:`CAMPAIGN_EXAMPLES` of them, seeded by ``TUBEJAX_PROPERTY_SEED``), as a decorator."""
    n = CAMPAIGN_EXAMPLES or int(ci_examples)
    s = settings(max_examples=n, derandomize=_CAMPAIGN_SEED is None, deadline=None, database=None,
                 print_blob=True,
                 suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                        HealthCheck.data_too_large])

    def decorate(fn):
        fn = s(fn)
        return seed(int(_CAMPAIGN_SEED))(fn) if _CAMPAIGN_SEED is not None else fn

    return decorate


def note_case(case, ts=None) -> None:
    """Record what an example covered (``pytest --hypothesis-show-statistics`` lists it):
    the kinds of ``A``, ``U``, ``W`` and, given a transition system, whether it has edges."""
    for part in case.desc.split(", "):
        event(part)
    N = case.decomp.n_cells
    event("N <= 4 cells" if N <= 4 else "N 5..8 cells" if N <= 8 else "N > 8 cells")
    if ts is not None:
        event("edges" if ts.n_edges else "no edge")


# ------------------------------------------------------------------------- the edge check
def check_edge(ts, k: int) -> float:
    """The proof check of edge ``k`` of ``ts``; returns its float64 violation.

    Today: the float64 re-check of the stored evidence (``ts.violation(k) <= VERIFY_TOL``,
    docs/math/evidence.md). HOOK for the exact rational check (``tubejax/lp/evidence/exact.py``):
    add its one-line assertion here and every property test that checks edges runs it.
    """
    viol = ts.violation(k)
    e = ts.edges[k]
    assert viol <= VERIFY_TOL, (f"edge {e.src}->{e.dst} (L={e.L}, {e.provenance}) violates "
                                f"its constraints by {viol:.3e} > {VERIFY_TOL}")
    # exact check (to be added): assert <exact check of edge k of ts>, ...
    return viol


# ------------------------------------------------------------------------- numbers
def _unit(draw, lo, hi):
    return draw(st.floats(lo, hi, allow_nan=False, allow_infinity=False))


def _vector(draw, n, lo, hi):
    return np.array([_unit(draw, lo, hi) for _ in range(n)])


def _rotation(draw, n: int, max_angle: float) -> np.ndarray:
    """A rotation of ``R^n`` (``n`` = 2 or 3) by at most ``max_angle`` radians."""
    th = _unit(draw, -max_angle, max_angle)
    c, s = np.cos(th), np.sin(th)
    if n == 2:
        return np.array([[c, -s], [s, c]])
    axis = _vector(draw, 3, -1.0, 1.0)
    assume(np.linalg.norm(axis) > 0.2)
    k = axis / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + s * K + (1 - c) * K @ K          # Rodrigues


A_KINDS = ("identity", "scaled", "rotation", "shear", "unstable", "general")


@st.composite
def state_matrix(draw, n: int, kinds=A_KINDS):
    """``(kind, A)`` with ``A`` of shape ``(n, n)``."""
    kind = draw(st.sampled_from(kinds))
    if kind == "identity":
        A = np.eye(n)
    elif kind == "scaled":
        A = _unit(draw, 0.7, 1.2) * np.eye(n)
    elif kind == "rotation":
        if n == 1:
            A = np.array([[-_unit(draw, 0.5, 1.1)]])           # a flip
        else:
            A = _unit(draw, 0.85, 1.1) * _rotation(draw, n, 0.8)
    elif kind == "shear":
        A = np.eye(n) + np.triu(np.array([[_unit(draw, -0.6, 0.6) for _ in range(n)]
                                          for _ in range(n)]), 1)
        if n == 1:
            A = np.array([[_unit(draw, 0.9, 1.1)]])
    elif kind == "unstable":
        if n >= 2 and draw(st.booleans()):
            A = _unit(draw, 1.05, 1.25) * _rotation(draw, n, 0.5)
        else:
            A = np.diag(_vector(draw, n, 1.02, 1.3))
    else:                                                   # any matrix, possibly singular
        A = np.array([[_unit(draw, -1.2, 1.2) for _ in range(n)] for _ in range(n)])
    return kind, A


@st.composite
def input_matrix(draw, n: int):
    """``B`` of shape ``(n, n)``: ``b I``, or ``b I`` plus a perturbation (full rank)."""
    b = _unit(draw, 0.3, 0.8)
    B = b * np.eye(n)
    if draw(st.booleans()):
        B = B + np.array([[_unit(draw, -0.25, 0.25) for _ in range(n)] for _ in range(n)])
        assume(abs(np.linalg.det(B)) > 0.05 ** n)
    return B


def _hull_around_zero(draw, n: int, r_lo: float, r_hi: float, extra: int) -> Polytope:
    """A random polytope containing a neighbourhood of 0: the hull of ``+-r_i e_i`` (random,
    possibly different radii per sign) and ``extra`` random points of norm <= ``r_hi``."""
    pts = []
    for d in range(n):
        for sgn in (-1.0, 1.0):
            e = np.zeros(n)
            e[d] = sgn * _unit(draw, r_lo, r_hi)
            pts.append(e)
    for _ in range(draw(st.integers(0, extra))):
        v = _vector(draw, n, -1.0, 1.0)
        nv = np.linalg.norm(v)
        assume(nv > 1e-3)
        pts.append(v / nv * _unit(draw, r_lo, r_hi))
    return Polytope.from_vertices(np.array(pts))


@st.composite
def input_set(draw, m: int, box_only: bool = False):
    """``(kind, U)``: a box around 0 (``'box'``) or a non-box polytope with 0 inside."""
    kinds = ("box",) if (box_only or m == 1) else ("box", "l1", "polytope")
    kind = draw(st.sampled_from(kinds))
    if kind == "box":
        lo = -_vector(draw, m, 0.5, 1.5)
        hi = _vector(draw, m, 0.5, 1.5)
        return kind, Polytope.box(lo, hi)
    if kind == "l1":
        return kind, one_norm_input_set(_unit(draw, 0.8, 2.0), m)
    U = _hull_around_zero(draw, m, 0.6, 1.5, 3)
    assume(np.min(U.h) > 0.1)
    return kind, U


@st.composite
def disturbance_set(draw, n: int, r_max: float = 0.2):
    """``(kind, W)``: a ball (radius 0 allowed), a box containing 0 or a polytope around 0."""
    kind = draw(st.sampled_from(("ball", "box", "polytope")))
    if kind == "ball":
        r = draw(st.one_of(st.just(0.0), st.floats(0.01, r_max)))
        return kind, Ball(n, r)
    if kind == "box":
        lo = -_vector(draw, n, 0.0, r_max)
        hi = _vector(draw, n, 0.0, r_max)
        assume(np.all(hi - lo > 1e-3))
        return kind, Polytope.box(lo, hi)
    return kind, _hull_around_zero(draw, n, 0.02, r_max, 3)


@st.composite
def linear_system(draw, n: int, box_u: bool = False, a_kinds=A_KINDS):
    """``(description, LinearSystem)`` with ``m = n``; ``box_u`` restricts ``U`` to boxes."""
    a_kind, A = draw(state_matrix(n, a_kinds))
    B = draw(input_matrix(n))
    u_kind, U = draw(input_set(n, box_u))
    w_kind, W = draw(disturbance_set(n))
    desc = f"A {a_kind}, U {u_kind}, W {w_kind}"
    return desc, LinearSystem(A=A, B=B, U=U, W=W)


# ------------------------------------------------------------------------- decompositions
@st.composite
def box_grid_decomposition(draw, n: int, max_div: int | None = None, aligned: bool = False):
    """A box grid in ``R^n`` with random widths and up to 2 random obstacle boxes (whole grid
    cells when ``aligned``; otherwise also boxes not aligned with the grid, which remove every
    cell they meet and leave the rest of those cells free but covered by no cell)."""
    max_div = max_div or {1: 6, 2: 3, 3: 2}[n]
    div = [draw(st.integers(2 if n > 1 else 3, max_div)) for _ in range(n)]
    if n == 3:
        div[2] = draw(st.integers(1, 2))
    width = _vector(draw, n, 0.6, 1.4)
    lo = _vector(draw, n, -2.0, 2.0)
    hi = lo + width * np.array(div)
    obstacles = []
    for _ in range(draw(st.integers(0, 2 if n > 1 else 1))):
        if aligned or draw(st.booleans()):              # one grid cell
            idx = np.array([draw(st.integers(0, d - 1)) for d in div])
            o_lo, o_hi = lo + idx * width, lo + (idx + 1) * width
        else:                                           # a box not aligned with the grid
            c = lo + _vector(draw, n, 0.0, 1.0) * (hi - lo)
            half = _vector(draw, n, 0.05, 0.4) * width
            o_lo, o_hi = c - half, c + half
        obstacles.append((o_lo, o_hi))
    try:
        d = box_grid(lo, hi, div, obstacles=obstacles, name=f"{n}-D box grid")
    except ValueError:                                  # the obstacles cover every cell
        assume(False)
    assume(d.n_cells >= 2)
    return d


@st.composite
def star_polygon(draw, k_min: int = 5, k_max: int = 8, r_lo: float = 1.0, r_hi: float = 2.2):
    """A simple star-shaped polygon around the origin, shape ``(k, 2)`` (counter-clockwise)."""
    k = draw(st.integers(k_min, k_max))
    ang = np.sort(np.array([_unit(draw, 0.0, 1.0) for _ in range(k)]) + np.arange(k)) * 2 * np.pi / k
    rad = _vector(draw, k, r_lo, r_hi)
    P = np.stack([rad * np.cos(ang), rad * np.sin(ang)], axis=1)
    # no near-duplicate vertices (a finding: tests/properties/test_prop_findings.py)
    assume(np.min(np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1)) > 0.05)
    poly = shapely.Polygon(P)
    assume(poly.is_valid and poly.area > 1.0)
    return P


@st.composite
def triangle_decomposition(draw):
    """Triangular cells: a random polygon workspace (with an optional obstacle, through
    :func:`parse_polygon_workspace`), or a fan of triangles built directly."""
    if draw(st.booleans()):
        boundary = draw(star_polygon())
        data = {"name": "random polygon", "boundary": boundary.tolist()}
        if draw(st.booleans()):
            c = _vector(draw, 2, -0.5, 0.5)
            s = _unit(draw, 0.15, 0.4)
            ob = c + s * np.array([[-1.0, -1.0], [1.0, -0.6], [0.7, 1.0], [-0.8, 0.8]])
            if shapely.Polygon(boundary).contains(shapely.Polygon(ob)):
                data["obstacles"] = [ob.tolist()]
        data["max_area"] = float(shapely.Polygon(boundary).area / draw(st.integers(3, 8)))
        d = parse_polygon_workspace(data)
    else:                                               # a fan around a centre, built directly
        P = draw(star_polygon(4, 7))
        c = np.zeros(2)
        Q = np.roll(P, -1, axis=0)
        assume(np.min(P[:, 0] * Q[:, 1] - P[:, 1] * Q[:, 0]) > 0.2)     # no flat triangle
        cells = tuple(Polytope.from_vertices(np.array([c, P[k], P[(k + 1) % len(P)]]))
                      for k in range(len(P)))
        outside = shapely.difference(shapely.box(-4, -4, 4, 4), shapely.Polygon(P))
        d = CellDecomposition(cells, (None,) * len(cells), (outside,), None, "triangle fan")
    assume(2 <= d.n_cells <= 14)
    return d


def decomposition(kind: str, aligned: bool = False):
    """The strategy of decomposition ``kind``: ``'box1'``, ``'box2'``, ``'box3'`` or ``'tri'``
    (``aligned``: box grids get whole-cell obstacles only, so cells and obstacles tile the box)."""
    if kind == "tri":
        return triangle_decomposition()
    return box_grid_decomposition(int(kind[-1]), aligned=aligned)


#: Cross-sections per decomposition kind (every one gives the same operator shape per kind).
ZSHAPES = {"box1": ("box", "cell"), "box2": ("box", "diamond", "cell"), "box3": ("box", "cell"),
           "tri": ("regular", "cell")}


class Case(NamedTuple):
    """One random abstraction problem."""

    kind: str
    decomp: CellDecomposition
    system: LinearSystem
    desc: str
    zshape: str
    z_scale: float
    eps_min: float

    def __repr__(self) -> str:
        s = self.system
        W = s.W
        w = (f"Ball(r={W.radius:.4g})" if isinstance(W, Ball)
             else f"Polytope(vertices={np.round(W.vertices, 6).tolist()})")
        cells = [np.round(c.vertices, 6).tolist() for c in self.decomp.cells]
        return (f"Case({self.kind}: {self.desc}; N={self.decomp.n_cells}, zshape={self.zshape}, "
                f"z_scale={self.z_scale:.4g}, eps_min={self.eps_min:.4g};\n  A={s.A.tolist()},\n"
                f"  B={s.B.tolist()},\n  U vertices={np.round(s.U.vertices, 6).tolist()},\n  W={w},\n"
                f"  cells={cells},\n  obstacles={self.decomp.obstacles})")


@st.composite
def case_strategy(draw, kind: str, box_u: bool = False, a_kinds=A_KINDS, aligned: bool = False):
    """A :class:`Case` of decomposition ``kind`` (``'box1'``, ..., ``'tri'``); ``box_u`` restricts
    ``U`` to boxes, ``a_kinds`` the kinds of ``A``, ``aligned`` the obstacles of box grids."""
    n = 2 if kind == "tri" else int(kind[-1])
    decomp = draw(decomposition(kind, aligned))
    desc, system = draw(linear_system(n, box_u, a_kinds))
    zshape = draw(st.sampled_from(ZSHAPES[kind]))
    z_scale = _unit(draw, 0.5, 2.0)
    eps_min = draw(st.sampled_from((0.0, 0.0, 0.0, 0.02)))
    return Case(kind, decomp, system, desc, zshape, z_scale, eps_min)
