"""Product-system files ``<stem>.json`` and ``<stem>.npz``, format ``"tubejax.product"`` version
:data:`PRODUCT_FORMAT_VERSION` (docs/reference/formats.md#product_transitionsjson).

A product system (docs/math/product.md) is saved as its edges and the factor verdicts that prove
them, not one tube per edge. Reading (:func:`read_product_files`) is strict: every field and array,
and every edge's verdicts in every group, so an edge is never in a readable file without its proofs.
Reading does not verify (``python -m tubejax verify`` does).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import numpy as np
import pydantic
from pydantic import BaseModel, ConfigDict, Field

from ..inputs.values import input_error, integer, real
from ..lp.declarations.tube_variables import Tube
from ..lp.evidence import QArray
from ..lp.evidence.check import ExactTube
from ..lp.evidence.prove import Proof
from ..lp.evidence.verdict import Verdict
from .file_format import (SystemEntry, TransitionFileError, _read_json, sha256_file, write_versioned_files)

__all__ = ["PRODUCT_FORMAT_NAME", "PRODUCT_FORMAT_VERSION", "PRODUCT_STEM", "ProductFileError", "ProductFile",
           "write_product_files", "read_product_files", "verdict_arrays", "verdicts_from_arrays", "is_product_run"]

PRODUCT_FORMAT_NAME = "tubejax.product"
PRODUCT_FORMAT_VERSION = 1
#: The stem of a product run's files.
PRODUCT_STEM = "product_transitions"
#: ``edge_variant`` of an edge proved by a joint LP.
JOINT_VARIANT = 2
_PROOF_CODES = {None: -1, "float": 0, "exact": 1}
_VERDICT_FIELDS = ("margin", "proof", "violation", "provenance", "nv", "p", "eps", "u", "exact")
_EXACT_FIELDS = ("exact_p", "exact_eps", "exact_u")


class ProductFileError(TransitionFileError):
    """A product-system file is missing, damaged, of another format, or inconsistent."""


class _Model(BaseModel):
    model_config = ConfigDict(strict=True, extra="forbid", frozen=True)


class GroupEntry(_Model):
    axes: list[integer(0)] = Field(min_length=1)
    inputs: list[integer(0)]
    n_factor_cells: integer(1)


class ProductFile(_Model):
    """The validated content of ``<stem>.json``."""

    format: Literal["tubejax.product"]
    version: integer(1)
    npz_sha256: str
    inputs: dict[str, Any] | None = None
    workspace: str = ""
    n_cells: integer(1)
    dim: integer(1)
    L_max: integer(1, 63)
    eps_min: real(0.0) = 0.0
    system: SystemEntry
    groups: list[GroupEntry] = Field(min_length=2)
    stats: dict[str, Any] = {}
    provenance: dict[str, Any] | None = None


def is_product_run(directory, stem: str = PRODUCT_STEM) -> bool:
    """Whether ``directory`` holds a product system's json (its content not checked)."""
    return (Path(directory) / f"{stem}.json").is_file()


# ------------------------------------------------------------------ verdicts <-> arrays
def verdict_arrays(prefix: str, verdicts) -> dict:
    """Flat arrays of confirmed tube verdicts (``status == 'edge'``), keys ``<prefix><field>``.

    ``margin``, ``violation`` (float, ``(K,)``), ``proof`` (int8: -1 none, 0 float, 1 exact),
    ``provenance`` (str), ``nv`` (vertices of each tube's ``Z``), ``p`` ``(sum L, n)``, ``eps``
    ``(sum L,)``, ``u`` ``(sum L nv, m)``, ``exact`` (bool: a rational tube is stored) and
    ``exact_p``, ``exact_eps``, ``exact_u`` (``"num/den"`` strings, concatenated over those).
    """
    ps, es, us, nv, ex, qs = [], [], [], [], [], ([], [], [])
    for v in verdicts:
        if v.status != "edge" or v.tube is None:
            raise ValueError(f"only confirmed edges are stored, got a verdict with status {v.status!r}")
        p, eps, u = (np.asarray(x, float) for x in v.tube)
        ps.append(p), es.append(eps), us.append(u.reshape(-1, u.shape[-1])), nv.append(u.shape[1])
        exact = getattr(v.proof, "exact", None)
        ex.append(exact is not None)
        if exact is not None:
            for q, arr in zip(qs, ExactTube.coerce(exact)):
                q.append(arr.to_strings().ravel())
    proof = [_PROOF_CODES[None if v.proof is None else v.proof.level] for v in verdicts]
    viol = [np.nan if v.proof is None else float(v.proof.violation) for v in verdicts]
    d = {"margin": np.array([float(v.margin) for v in verdicts]), "proof": np.array(proof, np.int8),
         "violation": np.array(viol, float), "provenance": np.array([str(v.provenance) for v in verdicts], str),
         "nv": np.array(nv, np.int64), "exact": np.array(ex, bool)}
    for name, parts, width in (("p", ps, 2), ("eps", es, 1), ("u", us, 2)):
        d[name] = np.concatenate(parts) if parts else np.zeros((0,) * width)
    for name, parts in zip(_EXACT_FIELDS, qs):
        d[name] = np.concatenate(parts) if parts else np.zeros(0, str)
    return {prefix + k: v for k, v in d.items()}


def verdicts_from_arrays(prefix: str, arrays: dict, L, dims: tuple, npath) -> list:
    """The verdicts :func:`verdict_arrays` stored, each tube of horizon ``L[k]`` in ``dims = (n, m)``.

    Raises
    ------
    ProductFileError
        Naming the file and the array, for a missing array or one of another dtype or shape.
    """
    n, m = dims
    L = np.asarray(L, dtype=np.int64)
    K = len(L)
    get = {f: _array(arrays, prefix + f, npath) for f in _VERDICT_FIELDS + _EXACT_FIELDS}
    for f in ("margin", "proof", "violation", "provenance", "nv", "exact"):
        if get[f].shape != (K,):
            raise _fail(npath, f"array {prefix + f!r}: expected shape ({K},), got {get[f].shape}")
    nv = get["nv"].astype(np.int64)
    if np.any(nv < 1):
        raise _fail(npath, f"array {prefix}nv: vertex counts must be >= 1")
    rows, urows = int(L.sum()), int((L * nv).sum())
    for f, shape in (("p", (rows, n)), ("eps", (rows,)), ("u", (urows, m))):
        if get[f].size == 0 and rows == 0:             # no verdicts: an empty array of any width
            get[f] = np.zeros(shape)
        elif get[f].shape != shape or get[f].dtype.kind != "f" or not np.all(np.isfinite(get[f])):
            raise _fail(npath, f"array {prefix + f!r}: expected finite floats of shape {shape}, got "
                               f"{get[f].dtype} {get[f].shape}")
    if not np.all(np.isin(get["proof"], (-1, 0, 1))):
        raise _fail(npath, f"array {prefix}proof: expected codes -1 (none), 0 (float), 1 (exact)")
    ex = get["exact"].astype(bool)
    exact_rows, exact_urows = int(L[ex].sum()), int((L * nv)[ex].sum())
    want = {"exact_p": exact_rows * n, "exact_eps": exact_rows, "exact_u": exact_urows * m}
    for f, size in want.items():
        if get[f].shape != (size,) or (size and get[f].dtype.kind != "U"):
            raise _fail(npath, f"array {prefix + f!r}: expected {size} 'num/den' strings, got {get[f].dtype} "
                               f"{get[f].shape}")
    r0 = np.concatenate([[0], np.cumsum(L)])
    u0 = np.concatenate([[0], np.cumsum(L * nv)])
    levels = {c: lvl for lvl, c in _PROOF_CODES.items()}
    out, q = [], {"exact_p": 0, "exact_eps": 0, "exact_u": 0}
    for k in range(K):
        Lk, nk = int(L[k]), int(nv[k])
        tube = Tube(get["p"][r0[k]:r0[k + 1]], get["eps"][r0[k]:r0[k + 1]],
                    get["u"][u0[k]:u0[k + 1]].reshape(Lk, nk, m))
        exact = None
        if ex[k]:
            parts = []
            for f, shape in (("exact_p", (Lk, n)), ("exact_eps", (Lk,)), ("exact_u", (Lk, nk, m))):
                size = int(np.prod(shape))
                try:
                    parts.append(QArray.from_strings(get[f][q[f]:q[f] + size].reshape(shape)))
                except (ValueError, ZeroDivisionError) as exc:
                    raise _fail(npath, f"array {prefix + f!r}: expected 'num/den' strings ({exc})") from None
                q[f] += size
            exact = ExactTube(*parts)
        level = levels[int(get["proof"][k])]
        proof = None if level is None else Proof(level, float(get["violation"][k]), None, exact, "read from file")
        out.append(Verdict("edge", float(get["margin"][k]), tube, str(get["provenance"][k]), proof))
    return out


# ------------------------------------------------------------------ writing
def write_product_files(directory, body: dict, arrays: dict, stem: str = PRODUCT_STEM) -> tuple[Path, Path]:
    """Write ``arrays`` to ``<stem>.npz``, then ``body`` (plus format, version and npz hash) to ``<stem>.json``.

    Both atomically (a temporary file, then a rename), the npz first; a ``"provenance"`` record is
    added to the body (:func:`tubejax.transitions.provenance.stamp`).
    """
    return write_versioned_files(directory, stem, body, arrays, (PRODUCT_FORMAT_NAME, PRODUCT_FORMAT_VERSION))


# ------------------------------------------------------------------ reading
def _fail(path, what: str) -> ProductFileError:
    return ProductFileError(f"{path}: {what}")


def _array(arrays: dict, key: str, npath) -> np.ndarray:
    if key not in arrays:
        raise _fail(npath, f"missing array {key!r}")
    return arrays[key]


def _ints(arrays: dict, key: str, npath, shape: tuple, lo: int = 0, hi: int | None = None) -> np.ndarray:
    a = _array(arrays, key, npath)
    if a.dtype.kind not in "iu" or a.shape != shape:
        raise _fail(npath, f"array {key!r}: expected integers of shape {shape}, got {a.dtype} {a.shape}")
    a = a.astype(np.int64, copy=False)                 # the file's own int64 array: no second copy
    bad = (a < lo) | (a > hi if hi is not None else False)
    if np.any(bad):
        raise _fail(npath, f"array {key!r}: value {int(a[bad].ravel()[0])} at index "
                           f"{np.argwhere(bad)[0].tolist()} outside [{lo}, {'inf' if hi is None else hi}]")
    return a


def read_product_files(directory, stem: str = PRODUCT_STEM) -> tuple[ProductFile, dict]:
    """Read and validate ``<stem>.json`` and ``<stem>.npz`` (module docstring).

    Returns
    -------
    doc : ProductFile
    arrays : dict of str -> ndarray

    Raises
    ------
    ProductFileError
        Naming the file and the field or array, for anything missing, damaged or inconsistent, and
        for an edge without its proofs in the file.
    """
    directory = Path(directory)
    jpath, npath = directory / f"{stem}.json", directory / f"{stem}.npz"
    try:
        data = _read_json(jpath)
    except TransitionFileError as exc:
        raise ProductFileError(str(exc)) from None
    if data.get("format") != PRODUCT_FORMAT_NAME:
        raise _fail(jpath, f"field 'format' is {data.get('format')!r}, expected {PRODUCT_FORMAT_NAME!r}")
    if data.get("version") != PRODUCT_FORMAT_VERSION or isinstance(data.get("version"), bool):
        raise _fail(jpath, f"field 'version' is {data.get('version')!r}, this tubejax reads version "
                           f"{PRODUCT_FORMAT_VERSION}")
    try:
        doc = ProductFile.model_validate(data)
    except pydantic.ValidationError as exc:
        err = input_error(exc)
        raise _fail(jpath, "; ".join(f"field '{f}': {m}" for f, m in err.problems[:5])) from None
    if not npath.is_file():
        raise _fail(npath, "no such file (the edges and their factor proofs)")
    if sha256_file(npath) != doc.npz_sha256:
        raise _fail(npath, f"its SHA-256 differs from {jpath.name}'s 'npz_sha256': the two files do not belong "
                           "together, or one was modified")
    try:
        with np.load(npath, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except Exception as exc:                      # noqa: BLE001 -- any damage is one clear error
        raise _fail(npath, f"cannot read the npz ({type(exc).__name__}: {exc}); the file is damaged") from None
    fv = arrays.get("format_version")
    if fv is None or fv.shape != () or fv.dtype.kind not in "iu" or int(fv) != doc.version:
        raise _fail(npath, f"array 'format_version' is {None if fv is None else fv.tolist()!r}, expected {doc.version}")
    _check_product_arrays(doc, arrays, npath, jpath)
    return doc, arrays


def _has_duplicates(code: np.ndarray) -> bool:
    """Whether the integers ``code`` ``(E,)`` repeat: a comparison when they increase (a saved system's
    edges are sorted by ``(src, dst)``), else one sort (``np.unique``'s hash table is slower at millions)."""
    if np.all(code[1:] > code[:-1]):
        return False
    code = np.sort(code)
    return bool(np.any(code[1:] == code[:-1]))


def _check_product_arrays(doc: ProductFile, arrays: dict, npath: Path, jpath: Path) -> None:
    N, G, L_max = doc.n_cells, len(doc.groups), doc.L_max
    axes = sorted(a for g in doc.groups for a in g.axes)
    if axes != list(range(doc.dim)):
        raise _fail(jpath, f"field 'groups': the groups' axes {axes} are not a partition of 0..{doc.dim - 1}")
    E = len(_array(arrays, "edge_src", npath))
    src = _ints(arrays, "edge_src", npath, (E,), 0, N - 1)
    dst = _ints(arrays, "edge_dst", npath, (E,), 0, N - 1)
    L = _ints(arrays, "edge_L", npath, (E,), 1, L_max)
    var = _ints(arrays, "edge_variant", npath, (E,), 0, JOINT_VARIANT)
    margin = _array(arrays, "edge_margin", npath)
    if margin.shape != (E,) or margin.dtype.kind != "f":
        raise _fail(npath, f"array 'edge_margin': expected floats of shape ({E},), got {margin.dtype} {margin.shape}")
    self_pair = np.flatnonzero(src == dst)
    if self_pair.size:
        raise _fail(npath, f"edge {int(self_pair[0])}: {int(src[self_pair[0]])} -> {int(dst[self_pair[0]])} is a "
                           "self-pair, which is not a transition")
    if _has_duplicates(src * N + dst):
        raise _fail(npath, "arrays 'edge_src', 'edge_dst': a pair is listed twice")
    cf = np.stack([_ints(arrays, "cell_factor", npath, (N, G))[:, g] for g in range(G)], axis=1)
    for g, grp in enumerate(doc.groups):
        F = grp.n_factor_cells
        if np.any(cf[:, g] >= F):
            raise _fail(npath, f"array 'cell_factor': group {g} has {F} factor cells, column {g} names more")
        for what in ("cells", "Z"):
            nv = _ints(arrays, f"g{g}_{what}_nv", npath, (F,), 1)
            verts = _array(arrays, f"g{g}_{what}_vertices", npath)
            if verts.shape != (int(nv.sum()), len(grp.axes)) or verts.dtype.kind != "f":
                raise _fail(npath, f"array 'g{g}_{what}_vertices': expected floats of shape "
                                   f"({int(nv.sum())}, {len(grp.axes)}), got {verts.dtype} {verts.shape}")
        _ints(arrays, f"g{g}_key", npath, (len(_array(arrays, f"g{g}_key", npath)), 4))
    _check_proofs_present(doc, arrays, npath, (src, dst, L, var, cf))
    joint = np.flatnonzero(var == JOINT_VARIANT)
    je = _ints(arrays, "joint_edge", npath, (len(_array(arrays, "joint_edge", npath)),), 0, max(E - 1, 0))
    if not np.array_equal(np.sort(je), joint):
        miss = sorted(set(joint.tolist()) - set(je.tolist()))
        what = (f"edge {miss[0]} ({int(src[miss[0]])} -> {int(dst[miss[0]])}, L={int(L[miss[0]])}) is a joint edge "
                "without its joint verdict" if miss else "it lists edges that are not joint edges")
        raise _fail(npath, f"array 'joint_edge': {what}")


def _check_proofs_present(doc: ProductFile, arrays: dict, npath: Path, edges) -> None:
    """Every factor-proved edge has an edge verdict in every group at its ``L`` and variant."""
    src, dst, L, var, cf = edges
    factor = np.flatnonzero(var != JOINT_VARIANT)
    F_max = max(grp.n_factor_cells for grp in doc.groups)
    small = np.int32 if 2 * (doc.L_max + 1) * F_max ** 2 < 2 ** 31 else np.int64   # codes of half the bytes
    fsrc, fdst, fL, fvar = (a if len(factor) == len(var) else a[factor] for a in (src, dst, L, var))
    fL, fvar = fL.astype(small), fvar.astype(small)      # in range (checked): 0..2, 1..L_max
    for g, grp in enumerate(doc.groups):
        F, L1 = grp.n_factor_cells, doc.L_max + 1
        key = _array(arrays, f"g{g}_key", npath).astype(np.int64)
        if len(key) and (np.any(key[:, 0] > 1) or np.any(key[:, 1] < 1) or np.any(key[:, 1] > doc.L_max)
                         or np.any(key[:, 2:] >= F)):
            raise _fail(npath, f"array 'g{g}_key': a (variant, L, a, b) outside (0..1, 1..{doc.L_max}, 0..{F - 1})")
        if len(key) and np.any((key[:, 2] == key[:, 3]) & (key[:, 0] == 1)):
            raise _fail(npath, f"array 'g{g}_key': a self-pair stored as 'source' (it is stored once, as 'box')")

        def codes(v, Ls, a, b):
            v = np.where(a == b, 0, v)                       # a self-pair's 'source' LP is its 'box' LP
            return ((v * L1 + Ls) * F + a) * F + b

        have = codes(key[:, 0], key[:, 1], key[:, 2], key[:, 3])
        if len(np.unique(have)) != len(have):
            raise _fail(npath, f"array 'g{g}_key': a factor LP is listed twice")
        col = cf[:, g].astype(small)                         # in 0..F-1 (checked)
        need = codes(fvar, fL, col[fsrc], col[fdst])
        missing = ~np.isin(need, have)
        if missing.any():
            k = int(factor[np.flatnonzero(missing)[0]])
            raise _fail(npath, f"edge {k} ({int(src[k])} -> {int(dst[k])}, L={int(L[k])}, safe set "
                               f"{('box', 'source')[int(var[k])]!r}) has no factor proof in group {g} (factor pair "
                               f"{int(cf[src[k], g])} -> {int(cf[dst[k], g])}): an edge is never in the file "
                               f"without its proofs ({int(missing.sum())} such edges)")
