"""Save and load a :class:`~tubejax.abstraction.product_abstraction.ProductSystem` (docs/reference/formats.md#product_transitionsjson).

:func:`save_product` writes the files of :mod:`tubejax.transitions.product_file`, refusing an edge
whose proofs are missing. :func:`load_product` reads them strictly, rebuilds the problem from the
inputs record (or takes the caller's), detects its product structure again and refuses a file whose
structure or system differs. Loading re-checks no tube: ``python -m tubejax verify`` does.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..errors import InputError
from ..inputs import ProblemInputs
from ..lp.evidence.registry import product_methods
from ..model.product_structure import NotAProduct, ProductStructure, product_structure
from ..model.system import LinearSystem
from ..transitions.source_files import SavesSources
from ..transitions.product_file import (PRODUCT_STEM, ProductFileError, read_product_files, verdict_arrays,
                                        verdicts_from_arrays, write_product_files)
from .product_abstraction import JOINT, ProductOptions, ProductSystem, build_product_abstraction
from .product_factors import FactorTable, SAFE_VARIANTS
from .product_transitions import product_transition_system

__all__ = ["ProductProblem", "ProductRun", "save_product", "load_product", "product_refusal", "try_product"]


class ProductProblem(NamedTuple):
    """The problem of a product file given by the caller instead of its inputs record."""

    decomposition: object
    system: LinearSystem
    Z: tuple


def _polytopes_arrays(prefix: str, polys) -> dict:
    return {f"{prefix}_nv": np.array([P.n_vertices for P in polys], np.int64),
            f"{prefix}_vertices": np.concatenate([np.asarray(P.vertices, float) for P in polys])}


def _check_factor_proofs(ps: ProductSystem) -> None:
    """Every factor-proved edge has a confirmed verdict ``(variant, L, a, b)`` in every group's table (the
    edges' keys encoded as integers and looked up with one ``np.isin`` per group, not a lookup per edge)."""
    cf = ps.structure.cell_factor
    factor = ps.variant != JOINT
    missing = np.zeros((ps.n_edges, len(ps.tables)), bool)
    for g, t in enumerate(ps.tables):
        have = np.array([key for key, v in t.verdicts.items() if v.status == "edge"], np.int64).reshape(-1, 4).T
        need = (ps.variant, ps.L, cf[ps.src, g], cf[ps.dst, g])
        radix = [max(int(h.max(initial=0)), int(x.max(initial=0))) + 1 for h, x in zip(have, need)]

        def code(v, L, a, b):
            return ((np.asarray(v, np.int64) * radix[1] + L) * radix[2] + a) * radix[3] + b

        missing[:, g] = factor & ~np.isin(code(*need), code(*have))
    if missing.any():
        e = int(np.flatnonzero(missing.any(axis=1))[0])
        g = int(np.flatnonzero(missing[e])[0])
        raise ValueError(f"edge {int(ps.src[e])}->{int(ps.dst[e])} (L={int(ps.L[e])}): its factor LP has no confirmed "
                         f"verdict in group {g}; the system cannot be saved")


def save_product(ps: ProductSystem, directory, inputs: dict | None = None, stem: str = PRODUCT_STEM):
    """Write ``ps`` to ``directory/<stem>.npz|.json`` (:mod:`tubejax.transitions.product_file`).

    Parameters
    ----------
    ps : ProductSystem
    directory : str or Path
    inputs : dict, optional
        The :class:`~tubejax.inputs.ProblemInputs` record ``ps`` was computed from (what a verifier
        rebuilds the problem from); ``None``: the loader must be given the problem.
    stem : str

    Returns
    -------
    (Path, Path)
        The json and the npz.

    Raises
    ------
    ValueError
        An edge whose factor verdicts (or joint verdict) are not confirmed edges: it is never written.
    """
    st = ps.structure
    arrays = {"edge_src": ps.src.astype(np.int64), "edge_dst": ps.dst.astype(np.int64),
              "edge_L": ps.L.astype(np.int64), "edge_margin": ps.margin.astype(float),
              "edge_variant": ps.variant.astype(np.int64), "cell_factor": st.cell_factor.astype(np.int64)}
    _check_factor_proofs(ps)
    for g, (f, t) in enumerate(zip(st.factors, ps.tables)):
        keys = sorted(k for k, v in t.verdicts.items() if v.status == "edge" and not (k[0] == 1 and k[2] == k[3]))
        arrays[f"g{g}_key"] = np.array(keys, np.int64).reshape(-1, 4)
        arrays.update(verdict_arrays(f"g{g}_", [t.verdicts[k] for k in keys]))
        arrays.update(_polytopes_arrays(f"g{g}_cells", f.cells))
        arrays.update(_polytopes_arrays(f"g{g}_Z", f.Z))
    joint = np.flatnonzero(ps.variant == JOINT)
    jv = [ps.joint.get((int(ps.src[k]), int(ps.dst[k]))) for k in joint]
    if any(v is None or v.status != "edge" for v in jv):
        raise ValueError("a joint edge without its confirmed joint verdict; the system cannot be saved")
    arrays["joint_edge"] = joint.astype(np.int64)
    arrays.update(verdict_arrays("joint_", jv))
    body = {"inputs": inputs, "workspace": ps.decomposition.name, "n_cells": ps.n_cells, "dim": st.n,
            "L_max": ps.L_max, "eps_min": ps.eps_min, "system": ps.system.record(),
            "groups": [{"axes": list(f.axes), "inputs": list(f.inputs), "n_factor_cells": f.n_cells}
                       for f in st.factors],
            "stats": {**ps.stats, "variants": ["box", "source", "joint"]}}
    return write_product_files(directory, body, arrays, stem)


def _rebuild(doc, directory: Path, jpath: Path) -> ProductProblem:
    try:
        inputs = ProblemInputs.from_record(doc.inputs, search_dirs=[directory])
        decomp = inputs.build_decomposition()
        problem = ProductProblem(decomp, inputs.build_system(), tuple(inputs.build_cross_sections(decomp)))
    except (InputError, ValueError) as exc:
        raise ProductFileError(f"{jpath}: field 'inputs': the problem cannot be rebuilt from its sources: "
                               f"{str(exc).splitlines()[0]}") from None
    a = inputs.abstraction
    if (int(a.L_max), float(a.eps_min)) != (int(doc.L_max), float(doc.eps_min)):
        raise ProductFileError(f"{jpath}: fields 'L_max', 'eps_min' ({doc.L_max}, {doc.eps_min}) differ from the "
                               f"inputs record's ({a.L_max}, {a.eps_min})")
    return problem


def _compare_structure(doc, arrays, st: ProductStructure, system: LinearSystem, jpath, npath) -> None:
    """Refuse a file whose copied data differ from the problem's (each difference named)."""
    if doc.n_cells != len(st.cell_factor) or doc.dim != st.n:
        raise ProductFileError(f"{jpath}: fields 'n_cells', 'dim' ({doc.n_cells}, {doc.dim}) differ from the "
                               f"problem's ({len(st.cell_factor)}, {st.n})")
    differ = LinearSystem.from_record(doc.system.model_dump()).differences(system)
    if differ:
        raise ProductFileError(f"{jpath}: field 'system': {', '.join(differ)} differ from the problem's")
    groups = [(list(f.axes), list(f.inputs), f.n_cells) for f in st.factors]
    if [(g.axes, g.inputs, g.n_factor_cells) for g in doc.groups] != groups:
        raise ProductFileError(f"{jpath}: field 'groups' differs from the product structure detected from the "
                               f"problem: {groups} (axes, inputs, factor cells)")
    if not np.array_equal(arrays["cell_factor"], st.cell_factor):
        raise ProductFileError(f"{npath}: array 'cell_factor' differs from the structure detected from the problem")
    for g, f in enumerate(st.factors):
        for what, polys in (("cells", f.cells), ("Z", f.Z)):
            mine = _polytopes_arrays("x", polys)
            if not (np.array_equal(arrays[f"g{g}_{what}_nv"], mine["x_nv"])
                    and np.array_equal(arrays[f"g{g}_{what}_vertices"], mine["x_vertices"])):
                raise ProductFileError(f"{npath}: arrays 'g{g}_{what}_*' differ from group {g}'s factor {what} "
                                       "detected from the problem")


def _table(g: int, factor, doc, arrays, npath) -> FactorTable:
    key = arrays[f"g{g}_key"].astype(np.int64)
    F, L_max, n_g, m_g = factor.n_cells, doc.L_max, len(factor.axes), len(factor.inputs)
    verdicts = verdicts_from_arrays(f"g{g}_", arrays, key[:, 1], (n_g, m_g), npath)
    feasible = np.zeros((2, L_max, F, F), bool)
    margin = np.full((2, L_max, F, F), np.nan)
    table = {}
    for (v, L, a, b), verdict in zip(key.tolist(), verdicts):
        for vv in ((0, 1) if a == b else (v,)):         # a self-pair's 'source' LP is its 'box' LP
            table[(vv, L, a, b)] = verdict
            feasible[vv, L - 1, a, b] = True
            margin[vv, L - 1, a, b] = verdict.margin
    return FactorTable(g, factor, L_max, feasible, margin, table, 0.0, len(key), {})


def load_product(directory, problem: ProductProblem | None = None, stem: str = PRODUCT_STEM) -> ProductSystem:
    """Read a product system saved by :func:`save_product` (strictly; nothing is re-checked).

    Parameters
    ----------
    directory : str or Path
    problem : ProductProblem, optional
        The decomposition, system and cross-sections; default: rebuilt from the file's inputs record
        (files looked up by path and checked by SHA-256, then beside ``directory``).
    stem : str

    Raises
    ------
    ProductFileError
        Naming the file and the field: a missing, damaged or inconsistent file, an edge without its
        proofs, sources that cannot be rebuilt, or copied data that differ from the problem.
    """
    directory = Path(directory)
    jpath, npath = directory / f"{stem}.json", directory / f"{stem}.npz"
    doc, arrays = read_product_files(directory, stem)
    if problem is None:
        if doc.inputs is None:
            raise ProductFileError(f"{jpath}: field 'inputs' is null: give the problem (load_product(directory, "
                                   "ProductProblem(decomposition, system, Z))) to read a file without its sources")
        problem = _rebuild(doc, directory, jpath)
    decomp, system, Z = problem
    try:
        st = product_structure(decomp, system, tuple(Z))
    except NotAProduct as exc:
        raise ProductFileError(f"{jpath}: the problem is not a product: {exc}") from None
    _compare_structure(doc, arrays, st, system, jpath, npath)
    tables = tuple(_table(g, f, doc, arrays, npath) for g, f in enumerate(st.factors))
    src, dst, L = (arrays[k].astype(np.int64, copy=False) for k in ("edge_src", "edge_dst", "edge_L"))
    je = arrays["joint_edge"].astype(np.int64)
    jv = verdicts_from_arrays("joint_", arrays, L[je], (st.n, st.m), npath)
    joint = {(int(src[k]), int(dst[k])): v for k, v in zip(je.tolist(), jv)}
    for k, v in zip(je.tolist(), jv):
        if v.tube.u.shape[1] != Z[int(src[k])].n_vertices:
            raise ProductFileError(f"{npath}: joint edge {k}: its tube has {v.tube.u.shape[1]} vertices, the "
                                   f"source cell's Z {Z[int(src[k])].n_vertices}")
    for g, t in enumerate(tables):
        for (v, L_, a, b), verdict in t.verdicts.items():
            if verdict.tube.u.shape[1] != t.factor.Z[a].n_vertices:
                raise ProductFileError(f"{npath}: group {g} factor pair {a}->{b} (L={L_}, {SAFE_VARIANTS[v]}): its "
                                       f"tube has {verdict.tube.u.shape[1]} vertices, its Z {t.factor.Z[a].n_vertices}")
    return ProductSystem(decomp, system, tuple(Z), st, tables, src, dst, L,
                         arrays["edge_margin"].astype(float, copy=False),
                         arrays["edge_variant"].astype(np.int64, copy=False), joint, int(doc.L_max), float(doc.eps_min),
                         dict(doc.stats))



class ProductRun(SavesSources):
    """A product system as the transition system to plan and simulate over
    (:func:`~tubejax.abstraction.product_transitions.product_transition_system`), saved as a product system.

    ``product`` is the :class:`ProductSystem`; :meth:`save` writes the workspace text given as text (if any)
    and the product files (:func:`save_product`), which ``python -m tubejax verify DIR`` verifies.
    """

    product: ProductSystem = None

    @classmethod
    def of_product(cls, ps: ProductSystem, inputs: dict | None = None, files=()) -> "ProductRun":
        """The run of ``ps`` with its inputs record and the workspace text files (``(name, bytes)`` pairs)."""
        out = cls.of(product_transition_system(ps, inputs), files)
        out.product = ps
        return out

    def save(self, directory, stem: str = PRODUCT_STEM) -> tuple[Path, Path]:
        """Write the workspace text files, then ``directory/<stem>.npz|.json`` (:func:`save_product`)."""
        self.write_sources(directory)
        return save_product(self.product, directory, self.inputs, stem)


def product_refusal(method: str, min_margin: float, L_max: int) -> str:
    """Why the product path cannot solve these settings (``''``: it can)."""
    if method not in product_methods():
        return f"the product path solves the tube LP, not method {method!r}"
    if float(min_margin) > 0:
        return f"the product path solves Problem 2 (min_margin 0), not min_margin {min_margin}"
    if not 1 <= int(L_max) <= 63:
        return f"the product path takes L_max in 1..63, not {L_max}"
    return ""


def try_product(decomp, system, options: ProductOptions, *, Z, method: str = "tube", min_margin: float = 0.0,
                solve_batch=None, progress: bool = False) -> tuple:
    """The product system, or why the product path cannot solve this problem (what ``product=auto`` decides).

    Parameters
    ----------
    decomp, system, options, Z, solve_batch, progress
        As :func:`~tubejax.abstraction.product_abstraction.build_product_abstraction` (``Z``: the cells'
        cross-sections; ``None`` for a learned ``Z``, which is not a product).
    method, min_margin : str, float
        The run's method and required margin (the product path solves the tube LP, Problem 2).

    Returns
    -------
    (ProductSystem or None, str)
        The system and ``''``, or ``None`` and the reason (:func:`product_refusal`, or the part of the
        problem that couples the groups: :class:`~tubejax.model.product_structure.NotAProduct`).
    """
    why = product_refusal(method, min_margin, options.L_max)
    if not why and Z is None:
        why = "a learned Z is not a product of the groups' Z"
    if why:
        return None, why
    try:
        return build_product_abstraction(decomp, system, options, Z=tuple(Z), solve_batch=solve_batch,
                                         progress=progress), ""
    except NotAProduct as exc:
        return None, str(exc)
