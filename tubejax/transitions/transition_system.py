"""The finite transition system (Definition 2) with its evidence: the cells, the confirmed edges, one tube per
edge and all problem data needed to re-verify every edge from scratch, saved as ``<stem>.json`` and
``<stem>.npz`` (:mod:`tubejax.transitions.file_format`). Each edge has a proof level
(docs/math/evidence.md#proof-levels): ``'exact'``, ``'float'`` or ``None`` (settled by
:meth:`TransitionSystem.prove`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import networkx as nx
import numpy as np
import shapely

from ..model.geometry import Polytope
from .graph_export import transition_graph, write_graph
from ..reachability.reference_solvers import reference_verdict
from ..lp.evidence.registry import FORMULATIONS
from ..lp.evidence import prove_evidence, settle
from ..lp.evidence.decide import certificate_rows
from ..lp.evidence.safe_set import prove_safe_set
from ..lp.evidence.verdict import VERIFY_TOL
from ..model.problem import Pairs, TubeProblem, pair_problem, pair_problems
from .records import Edge, EdgeArrays, NonEdges
from ..model.system import LinearSystem
from .reading import system_from_document
from .file_format import (FORMAT_NAME, FORMAT_VERSION, TransitionFileError, read_transition_files,
                          write_transition_files)
from ..model.workspace.decomposition import CellDecomposition
from ..model.zassignment import ZAssignment, z_of_pair

__all__ = ["Edge", "TransitionSystem", "TransitionFileError", "FORMAT_NAME", "FORMAT_VERSION", "VERIFY_TOL"]


@dataclass(eq=False)
class TransitionSystem:
    """Cells, confirmed edges and their tubes.

    Attributes
    ----------
    Z : tuple of Polytope (length N) or ZAssignment
        The cross-section of the tubes leaving each cell (a ``ZAssignment`` also holds per-pair ``Z``:
        :meth:`z_of`).
    tubes : list
        The evidence of ``edges[k]``: a Tube (``tube``), an OpenLoopPlan (``openloop``) or None (``exact2d``).
    inputs : dict or None
        The :class:`~tubejax.inputs.ProblemInputs` record the system was computed from (what
        :mod:`tubejax.verify.verifier` rebuilds the problem from); ``None`` when unknown.
    min_margin : float
        The margin every edge was required to reach (0: Problem 2).
    nonedges : NonEdges or None
        Every refused (pair, ``L``) that reached a solver, with its evidence; ``None`` when unknown.
    margin_scaling : {'state', 'coefficients'}
        Margins as state-space distances, or per unit of the LP coefficients (a format-1/2 file being converted).
    certificate_rows : tuple of str or None
        The row families the non-edges' exact certificates index, as the file recorded them
        (:func:`~tubejax.lp.evidence.decide.certificate_rows`); ``None``: this tubejax's.
    """

    decomposition: CellDecomposition
    system: LinearSystem
    Z: tuple
    edges: list = field(default_factory=list)
    tubes: list = field(default_factory=list)
    eps_min: float = 0.0
    method: str = "tube"
    stats: dict = field(default_factory=dict)
    inputs: dict | None = None
    min_margin: float = 0.0
    nonedges: NonEdges | None = None
    margin_scaling: str = "state"
    certificate_rows: tuple | None = None
    _arrays: tuple = field(default=(None, None), init=False, repr=False, compare=False)

    @property
    def n_cells(self) -> int:
        return self.decomposition.n_cells

    @property
    def n_edges(self) -> int:
        return len(self.edges)

    def edge_index(self) -> dict:
        """``{(src, dst): k}`` (a dict of every edge: :meth:`find_edges` finds many without one)."""
        return {(e.src, e.dst): k for k, e in enumerate(self.edges)}

    def edge_arrays(self) -> EdgeArrays:
        """The edges' ``src``, ``dst``, ``L`` as arrays and their sorted pair key (:class:`EdgeArrays`), kept
        until ``edges`` is another object or changes length (replacing an edge in place, as :meth:`prove`
        does, keeps its pair and ``L``)."""
        stamp = (id(self.edges), len(self.edges), self.n_cells)
        if self._arrays[0] != stamp:
            self._arrays = (stamp, EdgeArrays.of(self.edges, self.n_cells))
        return self._arrays[1]

    def find_edges(self, sources, targets) -> np.ndarray:
        """The index of edge ``sources[i] -> targets[i]`` (broadcast arrays of cell ids), ``-1`` where there
        is none; of several edges of one pair the lowest index (:meth:`EdgeArrays.find`: a binary search)."""
        return self.edge_arrays().find(sources, targets)

    def z_of(self, i: int, j: int) -> Polytope:
        """The cross-section of pair ``(i, j)``'s tubes (:func:`~tubejax.model.zassignment.z_of_pair`)."""
        return z_of_pair(self.Z, i, j)

    def problem(self, k: int) -> TubeProblem:
        """The tube problem of edge ``k``, rebuilt from the stored data."""
        e = self.edges[k]
        return pair_problem(self.decomposition, self.system, self.z_of(e.src, e.dst), e.src, e.dst, e.L,
                            self.eps_min, self.min_margin)

    def problems(self, ks=None, chunk: int = 4096):
        """``(k, problem)`` of edges ``ks`` (default all), in that order, like :meth:`problem` but vectorised
        per ``chunk`` edges and horizon (:func:`~tubejax.model.problem.pair_problems`)."""
        ks = np.arange(self.n_edges) if ks is None else np.asarray(ks, dtype=int)
        d = self.decomposition
        for c0 in range(0, len(ks), chunk):
            part = ks[c0:c0 + chunk]
            src = np.array([self.edges[k].src for k in part], dtype=int)
            dst = np.array([self.edges[k].dst for k in part], dtype=int)
            Ls = np.array([self.edges[k].L for k in part], dtype=int)
            obstacle = d.obstacle_cases(src, dst)
            out = [None] * len(part)
            for L in np.unique(Ls).tolist():
                at = np.flatnonzero(Ls == L)
                pairs = Pairs(src[at], dst[at], obstacle[at])
                for a, prob in zip(at.tolist(), pair_problems(d, self.system, self.Z, pairs, L, self.eps_min,
                                                               min_margin=self.min_margin)):
                    out[a] = prob
            yield from zip(part.tolist(), out)

    @property
    def _solves_lp(self) -> bool:
        """Whether the method is a registered LP (its edges store evidence)."""
        form = FORMULATIONS.get(self.method)
        return form is not None and form.solves_lp

    def violation(self, k: int, prob: TubeProblem | None = None) -> float:
        """Max constraint violation of the stored evidence of edge ``k`` in float64 (its LP record's check;
        ``exact2d``: the polygon computation redone, 0 if the edge holds, inf otherwise)."""
        prob = self.problem(k) if prob is None else prob
        form = FORMULATIONS.get(self.method)
        if form is None:
            raise ValueError(f"unknown method {self.method!r}")
        if form.solves_lp:
            return form.violation(prob, self.tubes[k])
        return 0.0 if reference_verdict(self.method)(prob).status == "edge" else float("inf")

    def verify(self, tol: float = VERIFY_TOL) -> np.ndarray:
        """Re-check every stored tube; returns the float64 violations, shape ``(n_edges,)``.

        Every edge's float evidence is re-checked in float64; every edge that claims
        ``proof == 'exact'`` is re-proved: its evidence (the rational tube where one is
        stored) in exact arithmetic, and its safe set against the obstacles.

        Raises
        ------
        AssertionError
            If any edge's tube violates a constraint by more than ``tol``, or an edge
            claiming an exact proof fails it.
        """
        v = np.full(self.n_edges, np.nan)
        failed = []
        for k, prob in self.problems():
            v[k] = self.violation(k, prob)
            if v[k] <= tol and self.edges[k].proof == "exact":
                why = self._exact_failure(k, prob)
                if why:
                    failed.append((k, why))
        bad = np.flatnonzero(~(v <= tol))
        if bad.size:
            e = self.edges[bad[0]]
            raise AssertionError(f"{bad.size} edges fail re-verification, e.g. {e.src}->{e.dst} "
                                 f"(L={e.L}) with violation {v[bad[0]]:.3e} > {tol}")
        if failed:
            k, why = failed[0]
            e = self.edges[k]
            raise AssertionError(f"{len(failed)} edges claim an exact proof but fail it, e.g. "
                                 f"{e.src}->{e.dst} (L={e.L}): {why}")
        return v

    def _evidence(self, k: int):
        """The evidence that proves edge ``k``: its rational evidence if stored, else the float one."""
        e = self.edges[k]
        return e.exact if e.exact is not None else self.tubes[k]

    def _exact_failure(self, k: int, prob: TubeProblem) -> str:
        """'' when edge ``k`` (problem ``prob``) is proven exactly (evidence and safe set), else why not."""
        if not self._solves_lp:
            return f"method {self.method!r} stores no evidence to prove"
        e = self.edges[k]
        if e.exact is not None:                  # the float evidence must be the proven one, rounded
            rounded, stored = e.exact.to_float(), self.tubes[k]
            if any(np.shape(a) != np.shape(b) or not np.array_equal(a, b) for a, b in zip(rounded, stored)):
                return "the stored float evidence is not the rounding of the stored rational evidence"
        pr = prove_evidence(prob, self._evidence(k), resolve=False)
        if pr.level != "exact":
            return pr.note
        ok, why = prove_safe_set(prob.safe, self.decomposition.obstacles)
        return "" if ok else f"safe set: {why}"

    def prove(self, reprove: bool = False) -> dict:
        """Settle every edge's proof level (docs/math/evidence.md#proof-levels) and return the counts.

        An edge of unknown level (every edge, with ``reprove``) is proved exactly if it can be, else
        re-solved with HiGHS and rebuilt from the basis (:func:`~tubejax.lp.evidence.prove_evidence`). It
        stays ``'exact'`` only if its safe set is proven too (:func:`~tubejax.lp.evidence.safe_set.prove_safe_set`).

        Returns
        -------
        dict
            ``{'exact': n, 'float': n, 'unknown': n, 'seconds': s}``, also stored in
            ``stats['proof']``.
        """
        t0 = time.perf_counter()
        if self._solves_lp:
            todo = [k for k in range(self.n_edges) if self._evidence(k) is not None]  # else no evidence stored
            for k, prob in self.problems(todo):
                e = self.edges[k]
                if e.proof is None or reprove:
                    pr = prove_evidence(prob, self._evidence(k), resolve=True)
                    exact = e.exact
                    if pr.exact is not None:
                        self.tubes[k], pr = settle(pr, self.tubes[k])
                        exact = pr.exact
                    e = replace(e, proof=pr.level, violation=0.0 if pr.level == "exact" else float(pr.violation),
                                exact=exact)
                if e.proof == "exact":
                    ok, _ = prove_safe_set(prob.safe, self.decomposition.obstacles)
                    if not ok:
                        e = replace(e, proof="float", violation=float(self.violation(k, prob)))
                self.edges[k] = e
        counts = {lvl: sum(e.proof == lvl for e in self.edges) for lvl in ("exact", "float")}
        counts["unknown"] = sum(e.proof is None for e in self.edges)
        counts["seconds"] = time.perf_counter() - t0
        self.stats["proof"] = counts
        return counts

    def to_networkx(self) -> nx.DiGraph:
        """The graph as a ``networkx.DiGraph`` (:func:`tubejax.transitions.graph_export.transition_graph`:
        its attributes, all scalars, none ``None``), ``n_cells`` nodes and ``n_edges`` edges."""
        return transition_graph(self)

    def export(self, path, format: str | None = None) -> Path:
        """Write the graph as GraphML, GEXF or Graphviz DOT and return ``path``
        (:func:`tubejax.transitions.graph_export.write_graph`: its parameters and errors)."""
        return write_graph(self, path, format)

    # ------------------------------------------------------------------ files
    def to_json(self) -> dict:
        """The json body (:mod:`tubejax.transitions.file_format`), without format, version and npz hash."""
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
        return {
            "method": self.method, "workspace": d.name, "inputs": self.inputs,
            "cells": cells,
            "edges": [e.to_json() for e in self.edges],
            "stats": self.stats,
            "obstacles": obstacles,
            "system": self.system.record(),
            "eps_min": self.eps_min, "min_margin": self.min_margin, "margin_scaling": self.margin_scaling,
            "certificate_rows": list(self.certificate_rows or certificate_rows(self.method, self.system)),
        }

    def save(self, directory, stem: str = "transitions") -> tuple[Path, Path]:
        """Write ``directory/<stem>.npz`` then ``directory/<stem>.json`` atomically; returns both paths."""
        arrays = {}
        for i, Z in enumerate(self.Z):
            arrays[f"Z_{i}"] = Z.vertices
        if isinstance(self.Z, ZAssignment):        # per-pair Z: stored with each edge that uses one
            for k, e in enumerate(self.edges):
                if self.Z.has_pair(e.src, e.dst):
                    arrays[f"edge_{k}_Z"] = self.Z.of_pair(e.src, e.dst).vertices
        for k, t in enumerate(self.tubes):
            if t is not None:                      # Tube (p, eps, u) or OpenLoopPlan (u)
                for name, value in t._asdict().items():
                    arrays[f"edge_{k}_{name}"] = value
        for k, e in enumerate(self.edges):
            if e.exact is not None:                # ExactTube / ExactPlan: "num/den" strings
                for name, value in e.exact._asdict().items():
                    arrays[f"edge_{k}_exact_{name}"] = value.to_strings()
        if self.nonedges is not None:              # the evidence of every refused instance
            arrays.update(self.nonedges.arrays())
        return write_transition_files(directory, stem, self.to_json(), arrays)

    @classmethod
    def load(cls, directory, stem: str = "transitions", prove: bool = False) -> "TransitionSystem":
        """Read what :meth:`save` wrote, strictly (:func:`~tubejax.transitions.file_format.read_transition_files`).
        Loading does not verify: the problem data are the ones copied into the file
        (:func:`tubejax.verify.verifier.load_with_sources` rebuilds them from the recorded sources). Edges without
        a ``proof`` entry load with the level unknown; ``prove=True`` settles them (:meth:`prove`).

        Raises
        ------
        TransitionFileError
            Naming the file and the field, for a missing, damaged or inconsistent file.
        """
        doc, arr = read_transition_files(directory, stem)
        ts = system_from_document(cls, doc, arr, Path(directory) / f"{stem}.npz")
        if prove:
            ts.prove()
        return ts
