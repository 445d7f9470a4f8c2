"""A transition system as a graph: networkx, and files for Gephi, yEd and Graphviz
(docs/reference/formats.md#graph-files).

:func:`transition_graph` gives a ``networkx.DiGraph`` whose attributes are all strings, numbers or
booleans (an unknown one is left out), so GraphML and GEXF writers accept it as it is. GEXF and DOT
(written here, no pydot) place each node at its cell's centroid.
"""

from __future__ import annotations

from pathlib import Path

import networkx as nx

from ..errors import InputError

__all__ = ["EXPORT_FORMATS", "GEXF_SCALE", "transition_graph", "export_format", "write_graph", "write_dot"]

#: Graph file formats :func:`write_graph` writes, and the file suffixes that mean each.
EXPORT_FORMATS = {"graphml": (".graphml",), "gexf": (".gexf",), "dot": (".dot", ".gv")}
#: GEXF positions per workspace unit (Gephi draws nodes about 10 units wide).
GEXF_SCALE = 100.0


def _coordinate_names(n: int) -> list[str]:
    return ["x", "y", "z"][:n] if n <= 3 else [f"x{k}" for k in range(n)]


def transition_graph(ts) -> nx.DiGraph:
    """The transition system ``ts`` as a ``networkx.DiGraph`` (attributes: see the module docstring).

    Parameters
    ----------
    ts : TransitionSystem

    Returns
    -------
    networkx.DiGraph
        ``N`` nodes (cell ids) and one edge per transition; every attribute a ``str``, ``int``,
        ``float`` or ``bool``.
    """
    d = ts.decomposition
    G = nx.DiGraph(method=str(ts.method), workspace=str(d.name))
    names = _coordinate_names(d.dim)
    for i in range(ts.n_cells):
        attrs = {}
        if d.labels[i] is not None:
            attrs["region"] = str(d.labels[i])
        attrs.update({k: float(v) for k, v in zip(names, d.cells[i].centroid)})
        if d.grid is not None:
            attrs.update({f"grid_{k}": int(v) for k, v in enumerate(d.grid[i])})
        G.add_node(i, **attrs)
    for e in ts.edges:
        attrs = {"L": int(e.L), "weight": int(e.L), "margin": float(e.margin), "provenance": str(e.provenance)}
        if e.proof is not None:
            attrs["proof"] = str(e.proof)
        if e.violation is not None and e.proof != "exact":
            attrs["violation"] = float(e.violation)
        if e.rho_star is not None:
            attrs["rho_star"] = float(e.rho_star)
        G.add_edge(int(e.src), int(e.dst), **attrs)
    return G


def export_format(path, format: str | None = None) -> str:
    """The format of ``path``: ``format`` when given, else the one its suffix names.

    Raises
    ------
    InputError
        An unknown format, or no format and a suffix that names none.
    """
    if format is not None:
        if format not in EXPORT_FORMATS:
            raise InputError(f"format: expected one of {', '.join(EXPORT_FORMATS)}, got {format!r}")
        return format
    suffix = Path(path).suffix.lower()
    for name, suffixes in EXPORT_FORMATS.items():
        if suffix in suffixes:
            return name
    known = ", ".join(s for v in EXPORT_FORMATS.values() for s in v)
    raise InputError(f"path: cannot tell the format of {str(path)!r} from its suffix (expected {known}); "
                     f"pass format='graphml', 'gexf' or 'dot'")


def write_graph(ts, path, format: str | None = None) -> Path:
    """Write ``ts``'s graph (:func:`transition_graph`) to ``path`` as GraphML, GEXF or DOT.

    Parameters
    ----------
    ts : TransitionSystem
    path : str or Path
        The file to write (its directory must exist).
    format : {'graphml', 'gexf', 'dot'}, optional
        Default: from the suffix (``.graphml``, ``.gexf``, ``.dot`` or ``.gv``).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    InputError
        An unknown format (see :func:`export_format`).
    """
    path = Path(path)
    fmt = export_format(path, format)
    G = transition_graph(ts)
    if fmt == "graphml":
        nx.write_graphml(G, path)
    elif fmt == "gexf":
        names = _coordinate_names(ts.decomposition.dim)
        if ts.decomposition.dim in (2, 3):
            for _, a in G.nodes(data=True):
                pos = {axis: GEXF_SCALE * a[k] for axis, k in zip("xyz", names)}
                a["viz"] = {"position": {"x": pos["x"], "y": pos["y"], "z": pos.get("z", 0.0)}}
        nx.write_gexf(G, path)
    else:
        write_dot(G, path)
    return path


def _dot_value(v) -> str:
    if isinstance(v, bool):
        return f'"{str(v).lower()}"'
    if isinstance(v, int):
        return str(v)
    s = repr(v) if isinstance(v, float) else str(v)
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


def _dot_attrs(attrs: dict) -> str:
    return ", ".join(f"{k}={_dot_value(v)}" for k, v in attrs.items())


def write_dot(G: nx.DiGraph, path) -> Path:
    """Write a directed graph with scalar attributes as Graphviz DOT (see the module docstring).

    Nodes must be integers; a node with ``x`` and ``y`` also gets ``pos="x,y!"``.

    Parameters
    ----------
    G : networkx.DiGraph
    path : str or Path

    Returns
    -------
    Path
    """
    path = Path(path)
    lines = [f"// tubejax transition system: {G.number_of_nodes()} cells, {G.number_of_edges()} transitions",
             "digraph transitions {"]
    if G.graph:
        lines.append(f"  graph [{_dot_attrs(G.graph)}];")
    lines.append("  node [shape=circle];")
    for i, a in G.nodes(data=True):
        extra = {"pos": f"{a['x']!r},{a['y']!r}!"} if "x" in a and "y" in a else {}
        lines.append(f"  {int(i)} [{_dot_attrs({**a, **extra})}];")
    for i, j, a in G.edges(data=True):
        lines.append(f"  {int(i)} -> {int(j)} [{_dot_attrs(a)}];")
    lines.append("}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
