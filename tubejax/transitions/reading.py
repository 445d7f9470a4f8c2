"""Reading a transition system back: :func:`system_from_document` turns a validated transitions file
(:func:`~tubejax.transitions.file_format.read_transition_files`) into a :class:`TransitionSystem`,
for :meth:`TransitionSystem.load` and :func:`tubejax.verify.verifier.verify_directory`.
"""

from __future__ import annotations

import numpy as np
import shapely

from ..model.geometry import Polytope
from ..lp.evidence import QArray
from ..lp.evidence.verdict import VERIFY_TOL
from ..lp.evidence.registry import FORMULATIONS
from .records import Edge, NonEdges
from ..model.system import LinearSystem
from .file_format import TransitionFileError
from ..model.workspace.decomposition import CellDecomposition
from ..model.zassignment import ZAssignment

__all__ = ["system_from_document"]


def system_from_document(cls, doc, arr: dict, npath):
    """A transition system from a validated file (the data copied into it).

    Parameters
    ----------
    cls : type
        :class:`~tubejax.transitions.transition_system.TransitionSystem` or a subclass.
    doc : TransitionFile
        The validated ``<stem>.json`` (:func:`~tubejax.transitions.file_format.read_transition_files`).
    arr : dict of str -> array
        The ``<stem>.npz`` arrays: ``Z_{i}`` (n_v, n) per cell, ``edge_{k}_Z`` (n_v, n) per-pair
        ``Z``, the tube ``edge_{k}_p`` / ``_eps`` / ``_u`` (or the plan's ``edge_{k}_u``), and the
        rational evidence ``edge_{k}_exact_*`` as ``"num/den"`` strings.
    npath : Path
        The npz (errors name it or its json).

    Raises
    ------
    TransitionFileError
        Invalid problem data, a float-proof edge without its violation, or partial or malformed
        rational evidence (naming the file and the edge).
    """
    try:
        cells = tuple(Polytope.from_vertices(c.vertices) for c in doc.cells)
        labels = tuple(None if c.label is None else str(c.label) for c in doc.cells)
        grids = [c.grid for c in doc.cells]
        grid = np.array(grids, dtype=int) if all(g is not None for g in grids) else None
        obstacles = tuple(Polytope.from_vertices(o.vertices) if o.kind == "polytope"
                          else shapely.from_wkt(o.wkt) for o in doc.obstacles)
        decomp = CellDecomposition(cells, labels, obstacles, grid, doc.workspace)
        system = LinearSystem.from_record(doc.system.model_dump())
        Z = tuple(Polytope.from_vertices(arr[f"Z_{i}"]) for i in range(len(cells)))
        pair_z = {(e.src, e.dst): Polytope.from_vertices(arr[f"edge_{k}_Z"])
                  for k, e in enumerate(doc.edges) if f"edge_{k}_Z" in arr}
        if pair_z:
            Z = ZAssignment(Z, pair_z)
    except (ValueError, shapely.errors.GEOSException) as exc:
        raise TransitionFileError(f"{npath.with_suffix('.json')}: the problem data in the file is invalid "
                                  f"({str(exc).splitlines()[0]})") from None
    method = doc.method
    edges = [Edge(e.src, e.dst, e.L, e.margin, e.provenance, *_proof_fields(e, k, npath.with_suffix(".json")),
                  _exact_evidence(arr, k, method, npath), e.rho_star)
             for k, e in enumerate(doc.edges)]
    form = FORMULATIONS.get(method)
    if form is not None and form.evidence_type is not None:
        tubes = [form.evidence_type(*(arr[f"edge_{k}_{n}"] for n in form.evidence_names)) for k in range(len(edges))]
    else:
        tubes = [None] * len(edges)
    try:
        nonedges = NonEdges.from_arrays(arr)
    except ValueError as exc:
        raise TransitionFileError(f"{npath}: the non-edge evidence is malformed: {exc}") from None
    return cls(decomp, system, Z, edges, tubes, float(doc.eps_min), method, dict(doc.stats), doc.inputs,
               float(doc.min_margin), nonedges, doc.scaling,
               None if doc.certificate_rows is None else tuple(doc.certificate_rows))


def _proof_fields(e, k: int, jpath) -> tuple:
    """``(proof, violation)`` of the validated edge entry ``k`` of a transitions.json.

    A violation is what the run measured for a ``'float'`` edge, so it is at most
    :data:`~tubejax.lp.evidence.verdict.VERIFY_TOL` (an edge never enters unconfirmed); an
    ``'exact'`` edge has none (``0`` is accepted), an edge without a proof level none at all.
    """
    field = f"field 'edges[{k}].violation'"
    if e.proof is None:
        if e.violation is not None:
            raise TransitionFileError(f"{jpath}: {field} is {e.violation!r}, but the edge has no proof level "
                                      "('proof' is missing): a violation belongs to an edge with proof 'float'")
        return None, None
    if e.proof == "exact":
        if e.violation is not None and e.violation != 0:
            raise TransitionFileError(f"{jpath}: {field} is {e.violation!r}, but the edge claims proof 'exact' "
                                      "(its evidence satisfies Problem 2 exactly: no violation)")
        return "exact", 0.0
    if e.violation is None:
        raise TransitionFileError(f"{jpath}: {field} is missing, expected a finite "
                                  "number >= 0 for an edge with proof 'float'")
    if not e.violation <= VERIFY_TOL:
        raise TransitionFileError(f"{jpath}: {field} is {e.violation!r}, above the {VERIFY_TOL:g} a confirmed "
                                  "edge's evidence may violate Problem 2 by (docs/math/evidence.md#edges)")
    return "float", float(e.violation)


def _exact_evidence(arr, k: int, method: str, npath):
    """The rational evidence of edge ``k`` stored in the npz, or ``None``."""
    form = FORMULATIONS.get(method)
    if form is None or form.exact_type is None:
        return None
    names = form.evidence_names
    keys = [f"edge_{k}_exact_{n}" for n in names]
    present = [key in arr for key in keys]
    if not any(present):
        return None
    if not all(present):
        missing = [key for key, ok in zip(keys, present) if not ok]
        raise TransitionFileError(f"{npath}: edge {k} has rational evidence but lacks {', '.join(missing)}")
    try:
        vals = [QArray.from_strings(arr[key]) for key in keys]
    except (ValueError, ZeroDivisionError) as exc:
        raise TransitionFileError(f"{npath}: {keys[0]}...: expected arrays of 'num/den' strings ({exc})") from None
    return form.exact_type(*vals)
