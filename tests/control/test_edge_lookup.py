"""Vectorised edge access: ``TransitionSystem.edge_arrays`` and ``find_edges`` (a binary search on a sorted
pair key) against a dict of the edges built here, on a real abstraction, on a product system's edge arrays
and on random edge lists (missing pairs, duplicate pairs, no edges, cell ids out of range)."""

import jax

jax.config.update("jax_enable_x64", True)

from types import SimpleNamespace  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import given, settings, strategies as st  # noqa: E402

from tubejax.abstraction.product_transitions import ProductEdges  # noqa: E402
from tubejax.analyses.control import PlanningError, plan_sequence  # noqa: E402
from tubejax.analyses.control.planner import cells_text  # noqa: E402
from tubejax.model.geometry import Ball, Polytope  # noqa: E402
from tubejax.model.system import LinearSystem, box_input_set  # noqa: E402
from tubejax.model.workspace.decomposition import CellDecomposition  # noqa: E402
from tubejax.transitions import records  # noqa: E402
from tubejax.transitions.records import Edge, EdgeArrays  # noqa: E402
from tubejax.transitions.transition_system import TransitionSystem  # noqa: E402


def first_edge_of_pair(triples) -> dict:
    """``{(src, dst): lowest k}``, by a plain loop."""
    out = {}
    for k, (i, j, _) in enumerate(triples):
        out.setdefault((int(i), int(j)), k)
    return out


def row_system(n_cells, triples):
    """A transition system over unit boxes in a row with hand-made edges ``(i, j, L)``."""
    cells = tuple(Polytope.box([i, 0.0], [i + 1.0, 1.0]) for i in range(n_cells))
    d = CellDecomposition(cells, tuple(str(i) for i in range(n_cells)))
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    return TransitionSystem(d, s, (), [Edge(int(i), int(j), int(L), 0.0, "test") for i, j, L in triples], [])


def check_against_dict(ts, triples, sources, targets):
    want = first_edge_of_pair(triples)
    got = ts.find_edges(sources, targets)
    assert got.shape == np.broadcast_shapes(np.shape(sources), np.shape(targets)) and got.dtype == np.int64
    for i, j, k in zip(np.broadcast_to(sources, got.shape).ravel().tolist(),
                       np.broadcast_to(targets, got.shape).ravel().tolist(), got.ravel().tolist()):
        assert k == want.get((i, j), -1), (i, j)


@pytest.fixture(scope="module")
def corridor():
    from tubejax.abstraction import build_abstraction
    from tubejax.model.workspace.gridmap import load_grid_map
    d = load_grid_map("/work/shared/validation/corridor.txt")
    s = LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=box_input_set(1.0, 2), W=Ball(2, 0.2))
    return build_abstraction(d, s, L_max=10, progress=False)


def test_corridor_every_pair(corridor):
    ts = corridor
    triples = [(e.src, e.dst, e.L) for e in ts.edges]
    a = ts.edge_arrays()
    assert a.src.tolist() == [t[0] for t in triples] and a.dst.tolist() == [t[1] for t in triples]
    assert a.L.tolist() == [t[2] for t in triples]
    assert ts.edge_arrays() is a                                       # kept
    assert len(first_edge_of_pair(triples)) == ts.n_edges              # a real system: one edge per pair
    assert ts.edge_index() == first_edge_of_pair(triples)
    N = ts.n_cells
    check_against_dict(ts, triples, np.arange(N)[:, None], np.arange(N)[None, :])   # all N x N pairs
    assert ts.find_edges(ts.edge_arrays().src, ts.edge_arrays().dst).tolist() == list(range(ts.n_edges))
    assert ts.find_edges([N, -1, 0], [0, 0, N]).tolist() == [-1, -1, -1]            # ids out of range


def test_cache_follows_the_edge_list(corridor):
    ts = TransitionSystem(corridor.decomposition, corridor.system, corridor.Z, list(corridor.edges[:5]),
                          list(corridor.tubes[:5]))
    first = ts.edge_arrays()
    e = corridor.edges[7]
    ts.edges.append(e)                                                 # the length changes: rebuilt
    assert ts.edge_arrays() is not first and int(ts.find_edges(e.src, e.dst)) == 5
    ts.edges = ts.edges[:2]                                            # another list: rebuilt
    assert len(ts.edge_arrays().src) == 2 and int(ts.find_edges(e.src, e.dst)) == -1
    assert not ts.edge_arrays().src.flags.writeable                    # the kept arrays are read-only


triples_st = st.integers(1, 12).flatmap(lambda n: st.tuples(
    st.just(n), st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1), st.integers(1, 8)), max_size=40)))


@settings(max_examples=60, deadline=None)
@given(triples_st, st.lists(st.tuples(st.integers(-2, 14), st.integers(-2, 14)), max_size=30))
def test_random_edges_against_a_dict(case, queries):
    n, triples = case
    ts = row_system(n, triples)
    q = np.array(queries, dtype=np.int64).reshape(-1, 2)
    check_against_dict(ts, triples, q[:, 0], q[:, 1])                  # missing, duplicate, out-of-range pairs
    check_against_dict(ts, triples, np.arange(n)[:, None], np.arange(n)[None, :])
    assert ts.find_edges([], []).shape == (0,)


@settings(max_examples=30, deadline=None)
@given(triples_st)
def test_product_edge_arrays_are_read_without_records(case):
    n, triples = case
    t = np.array(triples, dtype=np.int64).reshape(-1, 3)
    ps = SimpleNamespace(src=t[:, 0], dst=t[:, 1], L=t[:, 2], margin=np.zeros(len(t)), variant=np.zeros(len(t), int))
    edges = ProductEdges(ps)
    a = EdgeArrays.of(edges, n)
    b = EdgeArrays.of(list(edges), n)                                  # the same edges as records
    for x, y in zip(a[:5], b[:5]):
        assert np.array_equal(x, y)
    q = np.arange(n)
    got = a.find(q[:, None], q[None, :])
    want = first_edge_of_pair(triples)
    assert all(got[i, j] == want.get((i, j), -1) for i in range(n) for j in range(n))


def test_scalar_and_empty():
    ts = row_system(3, [])
    assert int(ts.find_edges(0, 1)) == -1 and ts.find_edges(0, 1).shape == ()
    ts = row_system(3, [(0, 1, 2), (2, 1, 3), (0, 1, 1)])
    assert int(ts.find_edges(0, 1)) == 0 and int(ts.find_edges(2, 1)) == 1 and int(ts.find_edges(1, 2)) == -1
    assert records.EdgeArrays is EdgeArrays


def test_cells_text_and_the_planning_error():
    assert cells_text(range(5)) == "[0, 1, 2, 3, 4]"
    assert cells_text(range(100)) == "[" + ", ".join(map(str, range(20))) + ", ... (80 more)]"
    assert cells_text(range(40), 3, 2, "; x") == "[0, 1, 2, ... (35 more; x) ..., 38, 39]"
    # 60 cells reachable from the start after segment 1, none labelled b: the message lists 20 and a count
    n = 63
    labels = ["s", "a"] + [None] * 60 + ["b"]
    ts = row_system(n, [])
    ts.decomposition = CellDecomposition(ts.decomposition.cells, tuple(labels))
    ts.edges = [Edge(0, 1, 1, 0.0, "t")] + [Edge(1, j, 1, 0.0, "t") for j in range(2, 62)]
    with pytest.raises(PlanningError) as err:
        plan_sequence(ts, 0, ["a", "b"])
    msg = str(err.value)
    assert "any of the cells [1, 2, 3, " in msg and ", 20, ... (41 more)] reachable after segment 1" in msg
    with pytest.raises(PlanningError, match=r"no path from cell 62 \(it has no outgoing transition\)"):
        plan_sequence(ts, 62, ["a"])
    with pytest.raises(PlanningError, match=r"no path from cell 0 to any cell labelled b"):
        plan_sequence(ts, 0, ["b"])


@settings(max_examples=60, deadline=None)
@given(triples_st)
def test_planner_graph_is_the_cheapest_edge_per_pair(case):
    from tubejax.analyses.control.planner import _graph

    n, triples = case
    best = {}
    for k, (i, j, L) in enumerate(triples):                            # the lowest L, then the lowest index
        if (i, j) not in best or L < triples[best[i, j]][2]:
            best[i, j] = k
    pairs, cost, edge = _graph(row_system(n, triples))
    assert [tuple(p) for p in pairs.tolist()] == sorted(best)          # the pairs, sorted
    assert edge.tolist() == [best[p] for p in sorted(best)]
    assert cost.tolist() == [triples[best[p]][2] for p in sorted(best)]


@settings(max_examples=60, deadline=None)
@given(triples_st, st.integers(0, 3), st.data())
def test_layered_graph_is_the_coordinate_built_one(case, K, data):
    import scipy.sparse as sp

    from tubejax.analyses.control.planner import _graph, _layered_graph

    n, triples = case
    pairs, cost, _ = _graph(row_system(n, triples))
    cost = cost.astype(float)
    hits = [np.array(sorted(data.draw(st.sets(st.integers(0, n - 1)))), dtype=np.int64) for _ in range(K)]
    rows, cols, w = [], [], []                                         # the construction it replaced
    for layer in range(K + 1):
        rows.append(layer * n + pairs[:, 0])
        cols.append(layer * n + pairs[:, 1])
        w.append(cost)
        if layer < K:
            rows.append(layer * n + hits[layer])
            cols.append((layer + 1) * n + hits[layer])
            w.append(np.zeros(len(hits[layer])))
    want = sp.csr_matrix((np.concatenate(w), (np.concatenate(rows), np.concatenate(cols))), shape=((K + 1) * n,) * 2)
    got = _layered_graph(pairs, cost, hits, n)
    assert got.shape == want.shape
    for a in ("indptr", "indices", "data"):
        assert np.array_equal(getattr(got, a), getattr(want, a)), a
