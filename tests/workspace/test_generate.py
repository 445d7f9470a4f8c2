"""The seeded rooms-and-corridors generator."""

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from tubejax.model.workspace import parse_grid_map
from tubejax.model.workspace.generate import rooms_and_corridors, rooms_and_corridors_map


def free_components(text):
    free = np.array([[ch != "#" for ch in line] for line in text.splitlines()])
    ids = -np.ones(free.shape, dtype=int)
    ids[free] = np.arange(free.sum())
    a, b = [], []
    for dr, dc in ((0, 1), (1, 0)):
        both = free[:free.shape[0] - dr, :free.shape[1] - dc] & free[dr:, dc:]
        a.append(ids[:free.shape[0] - dr, :free.shape[1] - dc][both])
        b.append(ids[dr:, dc:][both])
    a, b = np.concatenate(a), np.concatenate(b)
    g = coo_matrix((np.ones(len(a)), (a, b)), shape=(free.sum(), free.sum()))
    return connected_components(g, directed=False)[0], free


@pytest.mark.parametrize("rows, cols, seed", [(12, 12, 0), (25, 40, 1), (60, 33, 7), (5, 5, 2)])
def test_maps_are_connected_rooms_with_walls(rows, cols, seed):
    text = rooms_and_corridors(rows, cols, seed)
    n_comp, free = free_components(text)
    assert n_comp == 1
    assert free.shape == (rows, cols)
    if rows >= 12:
        assert 0.55 < free.mean() < 0.95 and (~free).any()
    d = parse_grid_map(text)
    assert d.n_cells == free.sum() and d.cells_with_label("1") == [0] and d.cells_with_label("2") == [d.n_cells - 1]


def test_same_seed_same_map_other_seed_other_map():
    assert rooms_and_corridors(30, 30, seed=4) == rooms_and_corridors(30, 30, seed=4)
    assert rooms_and_corridors(30, 30, seed=4) != rooms_and_corridors(30, 30, seed=5)


@pytest.mark.parametrize("n", [100, 1000, 5000])
def test_map_of_about_n_free_cells(n):
    text = rooms_and_corridors_map(n, seed=0)
    free = sum(ch in ".12" for ch in text)
    assert abs(free - n) <= 0.06 * n
    assert text == rooms_and_corridors_map(n, seed=0)


@pytest.mark.parametrize("kw, match", [(dict(rows=0, cols=5), "rows and cols"),
                                       (dict(rows=5, cols=5, room=(4, 2)), "room must be")])
def test_bad_arguments(kw, match):
    with pytest.raises(ValueError, match=match):
        rooms_and_corridors(**kw)
    with pytest.raises(ValueError, match="free_cells"):
        rooms_and_corridors_map(0)
