"""The finite transition system (Definition 2) with its evidence.

A :class:`TransitionSystem` holds the cells, the confirmed edges
``(i, j, L, margin, provenance)``, one tube per edge, and all problem data
needed to re-verify every edge from scratch. It is saved as a versioned pair
of files: ``<stem>.json`` (graph, cells, system, stats) and ``<stem>.npz``
(tubes and cross-sections).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import networkx as nx
import numpy as np
import shapely

from .geometry import Ball, Polytope
from .lp.formulations.tube.dense import Tube, TubeProblem, tube_violation
from .lp.evidence.verdict import VERIFY_TOL
from .problem import pair_problem
from .system import LinearSystem
from .workspace.decomposition import CellDecomposition

__all__ = ["Edge", "TransitionSystem", "FORMAT_NAME", "FORMAT_VERSION", "VERIFY_TOL"]

FORMAT_NAME = "tubejax.transitions"
FORMAT_VERSION = 1


@dataclass(frozen=True)
class Edge:
    """A confirmed transition ``src -> dst`` in ``L`` steps with margin ``t*``."""

    src: int
    dst: int
    L: int
    margin: float
    provenance: str

    def to_json(self) -> dict:
        return {"from": self.src, "to": self.dst, "L": self.L, "margin": self.margin,
                "provenance": self.provenance}


@dataclass(eq=False)
class TransitionSystem:
    """Cells, confirmed edges and their tubes.

    Attributes
    ----------
    decomposition : CellDecomposition
    system : LinearSystem
    Z : tuple of Polytope         cross-section used for tubes leaving each cell, length N
    edges : list of Edge
    tubes : list                  evidence of ``edges[k]``: a Tube (method ``tube``), an
                                  OpenLoopPlan (``openloop``) or None (``exact2d``)
    eps_min : float
    method : str                  ``'tube'``, ``'openloop'`` or ``'exact2d'``
    stats : dict                  run statistics (counts, seconds, ...)
    """

    decomposition: CellDecomposition
    system: LinearSystem
    Z: tuple
    edges: list = field(default_factory=list)
    tubes: list = field(default_factory=list)
    eps_min: float = 0.0
    method: str = "tube"
    stats: dict = field(default_factory=dict)

    @property
    def n_cells(self) -> int:
        return self.decomposition.n_cells

    @property
    def n_edges(self) -> int:
        return len(self.edges)

    def edge_index(self) -> dict:
        """``{(src, dst): k}``."""
        return {(e.src, e.dst): k for k, e in enumerate(self.edges)}

    def problem(self, k: int) -> TubeProblem:
        """The tube problem of edge ``k``, rebuilt from the stored data."""
        e = self.edges[k]
        return pair_problem(self.decomposition, self.system, self.Z[e.src], e.src, e.dst, e.L,
                            self.eps_min)

    def violation(self, k: int) -> float:
        """Max constraint violation of the stored evidence of edge ``k`` (float64).

        ``tube``: the tube re-checked by :func:`tube_violation`; ``openloop``: the
        input plan re-simulated by :func:`tubejax.lp.formulations.openloop.dense.openloop_violation`;
        ``exact2d``: the polygon computation is redone (0 if the edge holds, inf otherwise).
        """
        prob = self.problem(k)
        if self.method == "tube":
            return tube_violation(prob, self.tubes[k])
        if self.method == "openloop":
            from .lp.formulations.openloop.dense import openloop_violation
            return openloop_violation(prob, self.tubes[k])
        if self.method == "exact2d":
            from .exact2d import exact2d_verdict
            return 0.0 if exact2d_verdict(prob).status == "edge" else float("inf")
        raise ValueError(f"unknown method {self.method!r}")

    def verify(self, tol: float = VERIFY_TOL) -> np.ndarray:
        """Re-check every stored tube; returns the violations, shape ``(n_edges,)``.

        Raises
        ------
        AssertionError
            If any edge's tube violates a constraint by more than ``tol``.
        """
        v = np.array([self.violation(k) for k in range(self.n_edges)])
        bad = np.flatnonzero(~(v <= tol))
        if bad.size:
            e = self.edges[bad[0]]
            raise AssertionError(f"{bad.size} edges fail re-verification, e.g. {e.src}->{e.dst} "
                                 f"(L={e.L}) with violation {v[bad[0]]:.3e} > {tol}")
        return v

    def to_networkx(self) -> nx.DiGraph:
        """A ``networkx.DiGraph``: nodes carry ``label`` (and ``grid``), edges ``L`` (the cost), ``margin``, ``provenance``."""
        G = nx.DiGraph()
        d = self.decomposition
        for i in range(self.n_cells):
            attrs = {"label": d.labels[i], "centroid": d.cells[i].centroid.tolist()}
            if d.grid is not None:
                attrs["grid"] = d.grid[i].tolist()
            G.add_node(i, **attrs)
        for e in self.edges:
            G.add_edge(e.src, e.dst, L=e.L, weight=e.L, margin=e.margin, provenance=e.provenance)
        return G

    # ------------------------------------------------------------------ files
    def to_json(self) -> dict:
        d = self.decomposition
        cells = []
        for i, P in enumerate(d.cells):
            c = {"id": i, "label": d.labels[i]}
            if d.grid is not None:
                c["grid"] = d.grid[i].tolist()
            c["vertices"] = P.vertices.tolist()
            cells.append(c)
        obstacles = []
        for o in d.obstacles:
            if isinstance(o, Polytope):
                obstacles.append({"kind": "polytope", "vertices": o.vertices.tolist()})
            else:
                obstacles.append({"kind": "wkt", "wkt": shapely.to_wkt(o, rounding_precision=-1)})
        W = self.system.W
        Wj = ({"kind": "ball", "radius": W.radius, "dim": W.dim} if isinstance(W, Ball)
              else {"kind": "polytope", "vertices": W.vertices.tolist()})
        return {
            "format": FORMAT_NAME, "version": FORMAT_VERSION, "method": self.method,
            "workspace": d.name,
            "cells": cells,
            "edges": [e.to_json() for e in self.edges],
            "stats": self.stats,
            "obstacles": obstacles,
            "system": {"A": self.system.A.tolist(), "B": self.system.B.tolist(),
                       "U": {"vertices": self.system.U.vertices.tolist()}, "W": Wj},
            "eps_min": self.eps_min,
        }

    def save(self, directory, stem: str = "transitions") -> tuple[Path, Path]:
        """Write ``directory/<stem>.json`` and ``directory/<stem>.npz``; returns both paths."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        jpath, npath = directory / f"{stem}.json", directory / f"{stem}.npz"
        arrays = {"format_version": np.array(FORMAT_VERSION)}
        for i, Z in enumerate(self.Z):
            arrays[f"Z_{i}"] = Z.vertices
        for k, t in enumerate(self.tubes):
            if t is not None:                      # Tube (p, eps, u) or OpenLoopPlan (u)
                for name, value in t._asdict().items():
                    arrays[f"edge_{k}_{name}"] = value
        np.savez_compressed(npath, **arrays)
        tmp = jpath.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(self.to_json(), indent=1))
        tmp.replace(jpath)
        return jpath, npath

    @classmethod
    def load(cls, directory, stem: str = "transitions") -> "TransitionSystem":
        """Read what :meth:`save` wrote (checks the format name and version)."""
        directory = Path(directory)
        jpath, npath = directory / f"{stem}.json", directory / f"{stem}.npz"
        data = json.loads(jpath.read_text())
        if data.get("format") != FORMAT_NAME:
            raise ValueError(f"{jpath}: field 'format' is {data.get('format')!r}, expected {FORMAT_NAME!r}")
        if data.get("version") != FORMAT_VERSION:
            raise ValueError(f"{jpath}: field 'version' is {data.get('version')!r}, "
                             f"this tubejax reads version {FORMAT_VERSION}")
        arr = np.load(npath)
        cells = tuple(Polytope.from_vertices(c["vertices"]) for c in data["cells"])
        labels = tuple(c["label"] for c in data["cells"])
        grid = (np.array([c["grid"] for c in data["cells"]], dtype=int)
                if data["cells"] and "grid" in data["cells"][0] else None)
        obstacles = tuple(Polytope.from_vertices(o["vertices"]) if o["kind"] == "polytope"
                          else shapely.from_wkt(o["wkt"]) for o in data["obstacles"])
        decomp = CellDecomposition(cells, labels, obstacles, grid, data.get("workspace", ""))
        s = data["system"]
        Wj = s["W"]
        W = Ball(Wj["dim"], Wj["radius"]) if Wj["kind"] == "ball" else Polytope.from_vertices(Wj["vertices"])
        system = LinearSystem(np.array(s["A"]), np.array(s["B"]),
                              Polytope.from_vertices(s["U"]["vertices"]), W)
        Z = tuple(Polytope.from_vertices(arr[f"Z_{i}"]) for i in range(len(cells)))
        edges = [Edge(int(e["from"]), int(e["to"]), int(e["L"]), float(e["margin"]), e["provenance"])
                 for e in data["edges"]]
        method = data.get("method", "tube")
        if method == "tube":
            tubes = [Tube(arr[f"edge_{k}_p"], arr[f"edge_{k}_eps"], arr[f"edge_{k}_u"])
                     for k in range(len(edges))]
        elif method == "openloop":
            from .lp.formulations.openloop.dense import OpenLoopPlan
            tubes = [OpenLoopPlan(arr[f"edge_{k}_u"]) for k in range(len(edges))]
        else:
            tubes = [None] * len(edges)
        return cls(decomp, system, Z, edges, tubes, float(data.get("eps_min", 0.0)),
                   method, data.get("stats", {}))
