"""Packing pytrees for the pool: per-instance and broadcast leaves round-trip."""

from typing import NamedTuple

import numpy as np

from tubejax.lp.engines.pool import Layout


class _T(NamedTuple):
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray


def _tree(B=5):
    rng = np.random.default_rng(0)
    return _T(rng.standard_normal((3, 2, B)), rng.standard_normal((4, 1)),
              rng.integers(0, 9, (B,)).astype(np.int32), rng.standard_normal((2, B)))


def test_pack_unpack_round_trip_with_broadcast_leaves():
    t = _tree()
    lay = Layout.of(t)
    assert [b for _, _, b in lay.leaves] == [False, True, False, False]
    P = lay.pack(t)
    assert [p.shape for p in P] == [(6 + 2, 5), (4, 1), (1, 5)]       # (f8, B), (f8, bcast), (i4, B)
    assert lay.broadcast == (False, True, False)
    back = lay.unpack(P)
    for u, v in zip(back, t):
        np.testing.assert_array_equal(u, v)
    shapes = [(s.shape, s.dtype) for s in lay.abstract(16)]
    assert shapes == [((8, 16), np.float64), ((4, 1), np.float64), ((1, 16), np.int32)]


def test_a_single_instance_has_no_broadcast_leaves():
    lay = Layout.of(_tree(B=1))
    assert not any(b for _, _, b in lay.leaves)
