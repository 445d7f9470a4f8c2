"""The bound propagation of tubejax.abstraction.safe_reach: the two-axis fast path equals the general one,
and following only the pairs that are still alive and still have kept horizons changes nothing."""

import numpy as np
import yaml

from reference_cases import CONF
from tubejax.abstraction.candidates import build_candidates
from tubejax.model.geometry import Ball
from tubejax.abstraction.safe_reach import _hull_facets_of_translates, _propagate_two_axis_rows
from tubejax.model.system import LinearSystem, box_input_set
from tubejax.model.workspace import box_grid


def _propagate_halfspaces(a, b, H, g, sweeps: int = 1):
    """The general propagation, for any rows (the reference of the two-axis fast path): shrink boxes ``[a, b]`` (shape ``(k, nv, n)``) to the halfspaces ``H x <= g`` (per pair,
    shapes ``(k, F, n)``, ``(k, F)``) by bound propagation: for a row ``h`` and axis ``e`` with
    ``h_e > 0``, ``x_e <= (g - sum_{o != e} min(h_o a_o, h_o b_o)) / h_e`` (and ``>=`` for
    ``h_e < 0``). Every point of the box in the halfspaces stays; sound for any number of sweeps.
    """
    Hk = H[:, None, :, :]                                              # (k, 1, F, n)
    gk = g[:, None, :, None]
    for _ in range(sweeps):
        lo_t = np.minimum(Hk * a[:, :, None, :], Hk * b[:, :, None, :])    # (k, nv, F, n)
        rest = np.sum(lo_t, axis=3, keepdims=True) - lo_t
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = (gk - rest) / Hk
        big = np.abs(Hk) > 1e-12
        b = np.minimum(b, np.min(np.where(big & (Hk > 0), bound, np.inf), axis=2, initial=np.inf))
        a = np.maximum(a, np.max(np.where(big & (Hk < 0), bound, -np.inf), axis=2, initial=-np.inf))
    return a, b


def test_two_axis_rows_give_the_general_bounds():
    rng = np.random.default_rng(0)
    n, k, nv = 4, 64, 16
    c_i = rng.integers(0, 5, (k, n)).astype(float)
    c_j = c_i + rng.integers(-2, 3, (k, n))
    H, g = _hull_facets_of_translates(c_i, c_j, np.full(n, 0.5), Ball(n, 0.02), 0.0)
    a = rng.uniform(-1, 4, (k, nv, n))
    b = a + rng.uniform(0, 3, (k, nv, n))
    ia, ib = (np.concatenate([t, t]) for t in np.triu_indices(n, k=1))
    assert np.count_nonzero(H, axis=2).max() == 2
    a1, b1 = _propagate_halfspaces(a, b, H, g)
    a2, b2 = (np.moveaxis(x, 0, 2) for x in _propagate_two_axis_rows(np.moveaxis(a, 2, 0), np.moveaxis(b, 2, 0),
                                                                    H, g, ia, ib))     # its boxes: axis first
    assert np.allclose(a1, a2, rtol=0, atol=1e-12) and np.allclose(b1, b2, rtol=0, atol=1e-12)
    assert (a2 > a).any() and (b2 < b).any()                     # the rows did cut


def test_safe_set_rule_on_a_4d_grid_is_unchanged_by_following_fewer_pairs(monkeypatch):
    """Without ``keep`` every pair is followed to L_max (the reference); with it, the same
    instances are kept."""
    import tubejax.abstraction.candidates as cands
    from tubejax.abstraction.safe_reach import constrained_reach

    ws = yaml.safe_load((CONF / "workspace" / "boxgrid4d.yaml").read_text())
    cfg = yaml.safe_load((CONF / "system" / "double_integrator.yaml").read_text())
    d = box_grid(ws["lower"], ws["upper"], [4, 4, 2, 2], obstacles=[tuple(o) for o in ws["obstacles"]])
    s = LinearSystem(A=np.array(cfg["A"], float), B=np.array(cfg["B"], float), U=box_input_set(cfg["U"]["bound"], 2),
                     W=Ball(4, 0.02))
    monkeypatch.setattr(cands, "VERTEX_LP_MIN_DIM", 10 ** 9)              # the safe-set rule alone
    fast = build_candidates(d, s, 6)
    monkeypatch.setattr(cands, "constrained_reach", lambda *a, keep=None, **k: constrained_reach(*a, **k))
    full = build_candidates(d, s, 6)
    assert fast.pruned == full.pruned and fast.pruned["safe_set_unreachable"] > 0
    assert np.array_equal(fast.src, full.src) and np.array_equal(fast.keep, full.keep)


def test_threaded_chunks_give_the_same_horizons(monkeypatch, paper_system):
    """constrained_reach runs its chunks of pairs in threads; each writes only its own rows."""
    import tubejax.abstraction.safe_reach as sr
    from tubejax.abstraction.pruning import reach_tables
    from tubejax.model.workspace import parse_grid_map
    from tubejax.model.workspace.generate import rooms_and_corridors
    d = parse_grid_map(rooms_and_corridors(24, 24, seed=2))
    s = paper_system(0.2)
    T = reach_tables(d, s, 10)
    rng = np.random.default_rng(0)
    src = rng.integers(0, d.n_cells, 5000)
    dst = (src + rng.integers(1, 40, 5000)) % d.n_cells
    obstacle = d.obstacle_cases(src, dst)
    monkeypatch.setattr(sr, "_THREADS", 1)
    one = sr.constrained_reach(d, s, T, src, dst, obstacle, chunk=512)
    monkeypatch.setattr(sr, "_THREADS", 2)
    two = sr.constrained_reach(d, s, T, src, dst, obstacle, chunk=512)
    np.testing.assert_array_equal(one, two)
    assert 0 < one.mean() < 1
