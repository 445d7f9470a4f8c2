"""GraphML, GEXF and DOT exports of a transition system: networkx's writers accept ``to_networkx()``,
and each file reads back to the same nodes, edges and attributes."""

import math
import re

import jax
import networkx as nx
import numpy as np
import pytest

from tubejax.abstraction import build_abstraction
from tubejax.errors import InputError
from tubejax.transitions.graph_export import GEXF_SCALE, export_format
from tubejax.transitions.transition_system import Edge
from tubejax.model.workspace import box_grid, parse_grid_map

jax.config.update("jax_enable_x64", True)

MAP = "1..#\n.#..\n..2A\n"


@pytest.fixture(scope="module")
def ts(paper_system):
    ts = build_abstraction(parse_grid_map(MAP), paper_system(0.1), L_max=5, progress=False)
    # one edge with a float proof, a violation and a critical disturbance: every optional attribute
    e = ts.edges[1]
    ts.edges[1] = Edge(e.src, e.dst, e.L, e.margin, e.provenance, "float", 3.5e-12, rho_star=0.125)
    return ts


def _same_graph(G, H, extra_node=(), extra_edge=()):
    assert sorted(G.nodes) == sorted(H.nodes)
    assert sorted(G.edges) == sorted(H.edges)
    for i in G.nodes:
        got = {k: v for k, v in H.nodes[i].items() if k not in extra_node}
        assert got == G.nodes[i], (i, got, G.nodes[i])
    for i, j in G.edges:
        got = {k: v for k, v in H.edges[i, j].items() if k not in extra_edge}
        assert got == G.edges[i, j], ((i, j), got, G.edges[i, j])


def test_to_networkx_holds_scalars_only(ts):
    G = ts.to_networkx()
    assert G.number_of_nodes() == ts.n_cells and G.number_of_edges() == ts.n_edges
    for _, a in list(G.nodes(data=True)) + [(None, a) for *_, a in G.edges(data=True)]:
        assert all(isinstance(v, (str, int, float, bool)) for v in a.values()), a
    d = ts.decomposition
    i = d.cells_with_label("A")[0]
    assert G.nodes[i]["region"] == "A"
    assert (G.nodes[i]["x"], G.nodes[i]["y"]) == tuple(d.cells[i].centroid)
    assert (G.nodes[i]["grid_0"], G.nodes[i]["grid_1"]) == tuple(d.grid[i])
    unlabelled = d.labels.index(None)
    assert "region" not in G.nodes[unlabelled]
    e0, e1 = ts.edges[0], ts.edges[1]
    assert G.edges[e0.src, e0.dst] == {"L": e0.L, "weight": e0.L, "margin": e0.margin, "provenance": e0.provenance,
                                       "proof": "exact"}
    assert G.edges[e1.src, e1.dst]["violation"] == 3.5e-12 and G.edges[e1.src, e1.dst]["rho_star"] == 0.125
    assert G.graph == {"method": "tube", "workspace": d.name}


def test_graphml_round_trip(ts, tmp_path):
    G = ts.to_networkx()
    nx.write_graphml(G, tmp_path / "direct.graphml")               # networkx's writer accepts it as it is
    path = ts.export(tmp_path / "t.graphml")
    H = nx.read_graphml(path, node_type=int)
    _same_graph(G, H)
    assert {k: H.graph[k] for k in ("method", "workspace")} == G.graph


def test_gexf_round_trip_with_positions(ts, tmp_path):
    G = ts.to_networkx()
    nx.write_gexf(G, tmp_path / "direct.gexf")
    path = ts.export(tmp_path / "t.gexf")
    H = nx.read_gexf(path, node_type=int)
    # the GEXF reader adds a display label (the node id) and an edge id, and reads weights as floats
    for i, j, a in H.edges(data=True):
        assert a["weight"] == G.edges[i, j]["weight"]
        a["weight"] = int(a["weight"])
    _same_graph(G, H, extra_node=("label", "viz"), extra_edge=("id",))
    for i, a in H.nodes(data=True):
        assert a["label"] == str(i)
        pos = a["viz"]["position"]
        assert math.isclose(pos["x"], GEXF_SCALE * G.nodes[i]["x"])
        assert math.isclose(pos["y"], GEXF_SCALE * G.nodes[i]["y"])


_ATTR = re.compile(r'(\w+)=("(?:[^"\\]|\\.)*"|[^,\s\]]+)')


def _read_dot(text: str):
    """A structural reader of what write_dot writes: nodes, edges and their attributes as strings."""
    lines = text.splitlines()
    assert lines[1] == "digraph transitions {" and lines[-1] == "}"
    nodes, edges, graph = {}, {}, {}

    def attrs(s):
        return {k: (v[1:-1].replace('\\"', '"').replace("\\\\", "\\") if v.startswith('"') else v)
                for k, v in _ATTR.findall(s)}

    for line in lines[2:-1]:
        if m := re.fullmatch(r"  graph \[(.*)\];", line):
            graph = attrs(m.group(1))
        elif m := re.fullmatch(r"  (\d+) -> (\d+) \[(.*)\];", line):
            edges[int(m.group(1)), int(m.group(2))] = attrs(m.group(3))
        elif m := re.fullmatch(r"  (\d+) \[(.*)\];", line):
            nodes[int(m.group(1))] = attrs(m.group(2))
        else:
            assert line == "  node [shape=circle];", line
    return graph, nodes, edges


def _as_text(v):
    return repr(v) if isinstance(v, float) else str(v).lower() if isinstance(v, bool) else str(v)


def test_dot_round_trip(ts, tmp_path):
    G = ts.to_networkx()
    path = ts.export(tmp_path / "t.dot")
    graph, nodes, edges = _read_dot(path.read_text())
    assert graph == {"method": "tube", "workspace": ts.decomposition.name}
    assert sorted(nodes) == sorted(G.nodes) and sorted(edges) == sorted(G.edges)
    for i, a in G.nodes(data=True):
        got = dict(nodes[i])
        assert got.pop("pos") == f"{a['x']!r},{a['y']!r}!"
        assert got == {k: _as_text(v) for k, v in a.items()}
        assert all(float(got[k]) == a[k] for k in ("x", "y"))
    for i, j, a in G.edges(data=True):
        assert edges[i, j] == {k: _as_text(v) for k, v in a.items()}
        assert float(edges[i, j]["margin"]) == a["margin"]         # shortest round-trip decimals
    assert 'violation="3.5e-12"' in path.read_text()               # exponents are quoted (not DOT numerals)


def test_dot_quotes_strings(tmp_path):
    from tubejax.transitions.graph_export import write_dot
    G = nx.DiGraph(workspace='a "quoted"\\path')
    G.add_node(0, region='x"y')
    G.add_node(1)
    G.add_edge(0, 1, provenance="p\nq", ok=True)
    text = write_dot(G, tmp_path / "q.dot").read_text()
    graph, nodes, edges = _read_dot(text)
    assert graph["workspace"] == 'a "quoted"\\path' and nodes[0]["region"] == 'x"y'
    assert edges[0, 1] == {"provenance": "p\\nq", "ok": "true"}


def test_nd_graphs(paper_system, tmp_path):
    from tubejax.model.geometry import Ball
    from tubejax.model.system import LinearSystem, box_input_set
    d = box_grid([0, 0, 0, 0], [2, 1, 1, 1], [2, 1, 1, 1])
    s = LinearSystem(A=np.eye(4), B=np.eye(4), U=box_input_set(1.0, 4), W=Ball(4, 0.05))
    ts = build_abstraction(d, s, L_max=3, progress=False)
    G = ts.to_networkx()
    assert {"x0", "x1", "x2", "x3", "grid_0", "grid_3"} <= set(G.nodes[0])
    H = nx.read_gexf(ts.export(tmp_path / "g.gexf"), node_type=int)
    assert "viz" not in H.nodes[0] and H.number_of_edges() == ts.n_edges
    assert "pos=" not in ts.export(tmp_path / "g.gv").read_text()


@pytest.mark.parametrize("path, fmt, want", [("a.graphml", None, "graphml"), ("a.GEXF", None, "gexf"),
                                             ("a.gv", None, "dot"), ("a.txt", "dot", "dot")])
def test_format_from_suffix(path, fmt, want):
    assert export_format(path, fmt) == want


def test_unknown_formats_are_refused(ts, tmp_path):
    with pytest.raises(InputError, match="cannot tell the format of .*a.txt.* pass format="):
        ts.export(tmp_path / "a.txt")
    with pytest.raises(InputError, match="format: expected one of graphml, gexf, dot, got 'png'"):
        ts.export(tmp_path / "a.graphml", format="png")
