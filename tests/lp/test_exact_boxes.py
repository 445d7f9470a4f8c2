"""The exact facets of a box and of two boxes' hull (:mod:`tubejax.lp.evidence.exact_boxes`)
against the face-lattice path (:func:`exact_hull`, :func:`exact_hull_in_order`)."""

import itertools
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tubejax.lp.evidence import exact_problem
from tubejax.lp.evidence.exact_boxes import (_hull_at_origin, _hull_of_boxes, boxes_hull_facets,
                                             boxes_hull_in_order, exact_box)
from tubejax.lp.evidence.exact_geometry import ExactGeometryError, exact_hull, exact_hull_in_order
from tubejax.lp.evidence.rational import QArray
from tubejax.model.geometry import Polytope

KINDS = ["random", "shared_face", "inside", "equal_axes", "one_axis", "same", "touching_corner"]


def _corners(lo, hi) -> np.ndarray:
    return np.array(list(itertools.product(*zip(lo, hi))), dtype=float)


def _pair(n: int, kind: str, rng, floats: bool):
    """Two boxes ``(alo, ahi), (blo, bhi)`` in ``R^n`` (integers, or floats with long binary expansions)."""
    alo = rng.integers(0, 5, n).astype(float)
    ahi = alo + rng.integers(1, 4, n)
    blo = rng.integers(0, 5, n).astype(float)
    bhi = blo + rng.integers(1, 4, n)
    k = int(rng.integers(n))
    if kind == "shared_face":                      # b on a's upper face along k
        blo[k], bhi[k] = ahi[k], ahi[k] + rng.integers(1, 3)
    elif kind == "inside":                         # b inside a, touching on some axes
        blo = alo + rng.integers(0, 2, n) * (ahi - alo) / 4
        bhi = ahi - rng.integers(0, 2, n) * (ahi - alo) / 4
    elif kind == "equal_axes":                     # equal on every other axis
        blo[::2], bhi[::2] = alo[::2], ahi[::2]
    elif kind == "one_axis":                       # differing on axis k only
        blo, bhi = alo.copy(), ahi.copy()
        blo[k], bhi[k] = alo[k] + 1, ahi[k] + 2
    elif kind == "same":
        blo, bhi = alo.copy(), ahi.copy()
    elif kind == "touching_corner":                # b's lower corner is a's upper corner
        blo, bhi = ahi.copy(), ahi + rng.integers(1, 3, n)
    if floats:
        alo, ahi, blo, bhi = (x * 0.1 + 0.013 for x in (alo, ahi, blo, bhi))
    return (alo, ahi), (blo, bhi)


def _facet_set(E) -> set:
    return {(tuple(a), b) for a, b in zip(E.H.tolist(), E.h.to_fractions().tolist())}


def _float_rows(E, rng):
    """``E``'s facets as float rows (unit norm), shuffled: ``(H, h)``."""
    H, h = np.array(E.H.tolist(), dtype=float), E.h.to_float()
    nrm = np.linalg.norm(H, axis=1)
    perm = rng.permutation(len(h))
    return H[perm] / nrm[perm, None], h[perm] / nrm[perm]


def _same(A, B) -> bool:
    return (A.V.num.tolist() == B.V.num.tolist() and A.V.den == B.V.den and A.H.tolist() == B.H.tolist()
            and A.h.to_fractions().tolist() == B.h.to_fractions().tolist() and A.scale.tolist() == B.scale.tolist())


def _cases():
    for n in (2, 3, 4, 5):
        for kind in KINDS:
            for floats in (False, True):
                for seed in range(3 if n < 5 else 1):
                    yield n, kind, floats, seed


@pytest.mark.parametrize("n, kind, floats, seed", list(_cases()))
def test_pair_hull_matches_face_lattice(n, kind, floats, seed):
    rng = np.random.default_rng(1000 * n + 10 * seed + floats)
    boxes = _pair(n, kind, rng, floats)
    V = np.vstack([_corners(*b) for b in boxes])
    ref = exact_hull(V)
    facets, vertices = boxes_hull_facets(boxes)
    assert set(facets.items()) == _facet_set(ref)
    # the vertices found span the same hull (independently: the face-lattice path on them alone)
    Vx = np.array([[float(x) for x in v] for v in vertices])
    assert all(Fraction(float(x)) == x for v in vertices for x in v)
    assert _facet_set(exact_hull(Vx)) == _facet_set(ref)
    for pts in (V, Vx):                            # all corners, or only the extreme ones
        H, h = _float_rows(ref, rng)
        got = boxes_hull_in_order(pts, H, h, list(boxes))
        assert got is not None and _same(got, exact_hull_in_order(pts, H, h))


@pytest.mark.parametrize("n", [2, 3, 4, 5])
def test_box_matches_face_lattice(n):
    rng = np.random.default_rng(n)
    lo = rng.uniform(-1, 1, n)
    V = _corners(lo, lo + rng.uniform(0.1, 1, n))[rng.permutation(2 ** n)]
    box = exact_box(V)
    H, h = _float_rows(exact_hull(V), rng)
    got = boxes_hull_in_order(V, H, h, [box])
    assert got is not None and _same(got, exact_hull_in_order(V, H, h))
    assert set(boxes_hull_facets([box])[1]) == {tuple(Fraction(x) for x in v) for v in V}


def test_fallbacks():
    rng = np.random.default_rng(7)
    boxes = _pair(4, "random", rng, True)
    V = np.vstack([_corners(*b) for b in boxes])
    H, h = _float_rows(exact_hull(V), rng)
    assert boxes_hull_in_order(V, H, h, list(boxes)) is not None
    # a facet missing: not the facets (the face-lattice path refuses too)
    assert boxes_hull_in_order(V, H[1:], h[1:], list(boxes)) is None
    with pytest.raises(ExactGeometryError):
        exact_hull_in_order(V, H[1:], h[1:])
    # a row tilted beyond the tolerance
    Ht = H.copy()
    Ht[0] += 1e-6
    assert boxes_hull_in_order(V, Ht, h, list(boxes)) is None
    # a row's offset off: no points on it
    ho = h.copy()
    ho[0] += 1e-3
    assert boxes_hull_in_order(V, H, ho, list(boxes)) is None
    # boxes that are not co(V)'s: shifted, or one of them only
    moved = [(boxes[0][0] + 0.5, boxes[0][1] + 0.5), boxes[1]]
    assert boxes_hull_in_order(V, H, h, moved) is None
    assert boxes_hull_in_order(V, H, h, [boxes[0]]) is None


def test_missing_vertex_is_not_the_boxes_hull():
    rng = np.random.default_rng(3)
    boxes = _pair(3, "random", rng, False)
    _, vertices = boxes_hull_facets(boxes)
    Vx = np.array([[float(x) for x in v] for v in vertices[1:]])    # co(Vx) is smaller than the hull
    H, h = _float_rows(exact_hull(Vx), rng)
    assert boxes_hull_in_order(Vx, H, h, list(boxes)) is None
    assert exact_hull_in_order(Vx, H, h).H.shape[0] == H.shape[0]


def test_flat_box_has_no_facets():
    with pytest.raises(ExactGeometryError):
        boxes_hull_facets([([0, 0], [1, -1])])
    assert boxes_hull_facets([([0, 0, 0], [1, 0, 2])]) is None
    assert boxes_hull_facets([([0, 0, 0], [1, 0, 2]), ([0, 0, 0], [2, 0, 1])]) is None


def test_polytope_entry_takes_the_fast_path(monkeypatch):
    """The safe set of two box cells and a box target: the same entries as the face-lattice path,
    and without it (that path made to fail)."""
    rng = np.random.default_rng(11)
    (alo, ahi), (blo, bhi) = _pair(4, "random", rng, True)
    Pa, Pb = Polytope.box(alo, ahi), Polytope.box(blo, bhi)
    S = Polytope.from_vertices(np.vstack([Pa.vertices, Pb.vertices]))
    want = [exact_hull_in_order(QArray.from_floats(P.vertices), P.H, P.h) for P in (S, Pb)]

    def refuse(*args):
        raise ExactGeometryError("the face-lattice path is not to run")

    exact_problem.clear_caches()
    monkeypatch.setattr(exact_problem, "exact_hull_in_order", refuse)
    try:
        got = [exact_problem._polytope_entry(S, hull_of=(Pa, Pb)), exact_problem._polytope_entry(Pb)]
    finally:
        exact_problem.clear_caches()
    assert [flag for _, flag in got] == [True, True]
    assert all(_same(g, w) for (g, _), w in zip(got, want))


@settings(max_examples=60, deadline=None)
@given(st.integers(2, 4).flatmap(lambda n: st.tuples(
    st.lists(st.tuples(st.integers(-8, 8), st.integers(1, 6)), min_size=n, max_size=n),
    st.lists(st.tuples(st.integers(-8, 8), st.integers(1, 6)), min_size=n, max_size=n),
    st.lists(st.integers(-6, 6), min_size=n, max_size=n), st.integers(0, 3))))
def test_a_hull_moved_from_the_origin_is_the_hull_solved_in_place(data):
    """_hull_of_boxes solves the boxes moved to the origin once (cached) and moves the answer back; it must be
    the elimination run on the boxes where they are: facets (normals, offsets, order), corners, vertices, D."""
    a, b, shift, e = data
    den = 2 ** e
    boxes = [([Fraction(lo + s, den) for (lo, _), s in zip(box, shift)],
              [Fraction(lo + w + s, den) for (lo, w), s in zip(box, shift)]) for box in (a, b)]
    moved = _hull_of_boxes(boxes)
    in_place = _hull_at_origin.__wrapped__(tuple((tuple(lo), tuple(hi)) for lo, hi in boxes))
    if in_place is None:
        assert moved is None
        return
    assert list(moved[0].items()) == list(in_place[0].items())
    assert np.array_equal(moved[1], in_place[1]) and moved[2] == in_place[2] and moved[3] == in_place[3]
