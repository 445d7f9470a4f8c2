"""Transition-system files ``<stem>.json`` and ``<stem>.npz``, format version :data:`FORMAT_VERSION`
(every field: docs/reference/formats.md#transitionsjson).

Both are written atomically, the npz first. Reading is strict: every field is validated
(:class:`TransitionFileError` names the file and the field), every edge joins two different cells
and has exactly its evidence. Versions 1 and 2 are refused with the command that converts them
(:data:`CONVERTER`).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import zipfile
import zlib
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import numpy as np
import pydantic
from pydantic import BaseModel, ConfigDict, Field

from ..errors import InputError
from ..inputs.values import integer, input_error, matrix, real
from ..inputs.values import label as region_label
from ..lp.evidence.registry import FORMULATIONS, method_names
from ..model.zshape.kinds import z_vertex_count_problem
from .provenance import stamp

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "READ_VERSIONS", "TransitionFileError", "TransitionFile",
           "read_transition_files", "write_transition_files", "write_versioned_files", "atomic_write", "sha256_file",
           "evidence_names", "json_safe", "validate_document", "read_npz"]

FORMAT_NAME = "tubejax.transitions"
#: Version written by this tubejax.
FORMAT_VERSION = 4
#: Versions it reads.
READ_VERSIONS = (3, 4)
#: The versions before 3 and the command that converts them to the current one.
OLD_VERSIONS = (1, 2)
CONVERTER = "python scripts/convert_transitions.py OLD_RUN NEW_RUN"


class TransitionFileError(InputError):
    """A transitions file is missing, damaged, of another format, or inconsistent with its npz."""


def sha256_file(path) -> str:
    """Hex SHA-256 of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


#: The methods a transition file may record: the registered LPs.
METHOD_NAMES = method_names()


def evidence_names(method: str) -> tuple[str, ...]:
    """The npz fields of one edge's float evidence for ``method`` (its LP record's; none for ``exact2d``)."""
    f = FORMULATIONS.get(method)
    return () if f is None else f.evidence_names


# ------------------------------------------------------------------ the JSON schema
class _Model(BaseModel):
    model_config = ConfigDict(strict=True, extra="forbid", frozen=True, populate_by_name=True)


class _Open(BaseModel):
    model_config = ConfigDict(strict=True, extra="allow", frozen=True)


class CellEntry(_Model):
    id: integer(0)
    label: region_label | None = None
    grid: list[Annotated[int, Field(strict=True)]] | None = None
    vertices: matrix("a list of vertices (rows of coordinates)")


class EdgeEntry(_Model):
    src: integer(0) = Field(alias="from")
    dst: integer(0) = Field(alias="to")
    L: integer(1)
    margin: real()
    provenance: str
    proof: Literal["exact", "float"] | None = None
    violation: real(0.0) | None = None
    rho_star: real() | None = None


class PolytopeObstacle(_Model):
    kind: Literal["polytope"]
    vertices: matrix("a list of vertices")


class WktObstacle(_Model):
    kind: Literal["wkt"]
    wkt: str


class BallW(_Model):
    kind: Literal["ball"]
    radius: real(0.0)
    dim: integer(1)


class PolytopeW(_Model):
    kind: Literal["polytope"]
    vertices: matrix("a list of vertices")


class InputSet(_Model):
    vertices: matrix("a list of vertices")


class SystemEntry(_Open):
    """``A``, ``B``, ``U``, ``W``; further keys are the system's state constraints, which
    :meth:`~tubejax.model.system.LinearSystem.from_record` reads and checks (naming the key)."""

    A: matrix("a matrix")
    B: matrix("a matrix")
    U: InputSet
    W: Annotated[Union[BallW, PolytopeW], Field(discriminator="kind")]


class TransitionFile(_Model):
    """The validated content of ``<stem>.json``."""

    format: Literal["tubejax.transitions"]
    version: integer(1)
    method: Literal[METHOD_NAMES] = "tube"
    workspace: str = ""
    inputs: dict[str, Any] | None = None
    npz_sha256: str | None = None
    cells: Annotated[list[CellEntry], Field(min_length=1)]
    edges: list[EdgeEntry]
    stats: dict[str, Any] = {}
    obstacles: list[Annotated[Union[PolytopeObstacle, WktObstacle], Field(discriminator="kind")]] = []
    system: SystemEntry
    eps_min: real(0.0) = 0.0
    min_margin: real(0.0, 1.0) = 0.0
    margin_scaling: Literal["state", "coefficients"] | None = None
    certificate_rows: list[str] | None = None
    provenance: dict[str, Any] | None = None

    @property
    def scaling(self) -> str:
        """How this file's margins are scaled (docs/math/margins.md#state-space-distances): its ``margin_scaling``,
        else ``'state'`` (every file read without the field; ``'coefficients'`` marks a file being converted)."""
        return self.margin_scaling or "state"


# ------------------------------------------------------------------ writing
def atomic_write(path: Path, write) -> None:
    """``write(file)`` into ``path`` through a temporary file (a binary file object), flushed to disk,
    then renamed: a reader sees the old file or the whole new one."""
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        write(f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def write_transition_files(directory, stem: str, body: dict, arrays: dict) -> tuple[Path, Path]:
    """Write ``arrays`` to ``<stem>.npz``, then ``body`` to ``<stem>.json`` (:func:`write_versioned_files`)."""
    return write_versioned_files(directory, stem, body, arrays, (FORMAT_NAME, FORMAT_VERSION))


def write_versioned_files(directory, stem: str, body: dict, arrays: dict, fmt: tuple[str, int]) -> tuple[Path, Path]:
    """Write ``<stem>.npz`` then ``<stem>.json`` of the format ``fmt = (name, version)``, both atomically.

    The npz gets ``format_version``; the json gets ``format``, ``version``, ``npz_sha256`` and a
    ``"provenance"`` record (:func:`tubejax.transitions.provenance.stamp`). Used by the transition
    files and the product files (:mod:`tubejax.transitions.product_file`).
    """
    name, version = fmt
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    jpath, npath = directory / f"{stem}.json", directory / f"{stem}.npz"

    atomic_write(npath, lambda f: np.savez_compressed(f, format_version=np.array(version), **arrays))
    doc = {"format": name, "version": version, "npz_sha256": sha256_file(npath), **json_safe(stamp(body))}
    text = json.dumps(doc, indent=1, allow_nan=False)
    atomic_write(jpath, lambda f: f.write(text.encode()))
    return jpath, npath


# ------------------------------------------------------------------ reading
def _fail(path: Path, what: str) -> TransitionFileError:
    return TransitionFileError(f"{path}: {what}")


def _missing_hint(jpath: Path) -> str:
    """Why ``jpath`` may be missing: other transition files beside it (another stem), or a run
    whose manifest says it is still running (interrupted); ``''`` when nothing says."""
    d = jpath.parent
    others = sorted(p.stem for p in d.glob("*.json") if p != jpath and (d / f"{p.stem}.npz").is_file())
    if others:
        return (f" (the directory holds the transition files of stem {', '.join(map(repr, others))}; --stem names "
                "the stem)")
    manifest = d / "rounds" / "manifest.json"
    if manifest.is_file():
        try:
            status = json.loads(manifest.read_text(encoding="utf-8")).get("status")
        except (OSError, UnicodeDecodeError, ValueError, AttributeError):
            status = None
        if status != "complete":                      # a run that never marked itself finished
            return " (the directory holds an interrupted run: rounds/; resume it or rerun)"
        return " (rounds/manifest.json says the run finished: its transition files were moved or deleted; rerun)"
    if (d / "rounds").is_dir():
        return (" (the directory holds round files, rounds/, but no manifest, rounds/manifest.json: which run they "
                "belong to is unknown, and they cannot be resumed; rerun the abstraction)")
    return ""


def _read_json(jpath: Path) -> dict:
    if jpath.is_dir() or not jpath.parent.is_dir():
        raise _fail(jpath, "expected a transitions file in a directory; "
                           f"{'it is a directory' if jpath.is_dir() else 'no such directory'}")
    if not jpath.exists():
        raise _fail(jpath, f"no such file{_missing_hint(jpath)}")
    try:
        text = jpath.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise _fail(jpath, f"cannot read ({exc})") from None

    def no_constants(name):
        raise ValueError(f"non-finite number {name}")

    try:
        data = json.loads(text, parse_constant=no_constants)
    except json.JSONDecodeError as exc:
        raise _fail(jpath, f"not valid JSON at line {exc.lineno}, column {exc.colno} ({exc.msg}); "
                           "the file is damaged or truncated") from None
    except ValueError as exc:
        raise _fail(jpath, f"{exc} (JSON numbers must be finite)") from None
    if not isinstance(data, dict):
        raise _fail(jpath, f"expected a JSON object, got {type(data).__name__}")
    return data


def _check_npz_array(npath: Path, arrays: dict, key: str, shape: tuple | None = None, strings: bool = False):
    if key not in arrays:
        raise _fail(npath, f"missing array {key!r}")
    a = arrays[key]
    if strings:
        if a.dtype.kind != "U":
            raise _fail(npath, f"array {key!r}: expected 'num/den' strings, got dtype {a.dtype}")
        return a
    if a.dtype.kind not in "fi" or (shape is not None and a.shape != shape):
        want = f"shape {shape}" if shape is not None else "numbers"
        raise _fail(npath, f"array {key!r}: expected float {want}, got dtype {a.dtype} and shape {a.shape}")
    a = a.astype(float)
    if not np.all(np.isfinite(a)):
        raise _fail(npath, f"array {key!r}: non-finite values")
    return a


def read_transition_files(directory, stem: str = "transitions") -> tuple[TransitionFile, dict]:
    """Read and validate ``<stem>.json`` and ``<stem>.npz``.

    Checks the format names and versions of both files, the npz hash recorded in the json,
    every field of the json, and that the npz holds exactly the evidence of the listed edges
    (shapes included) and one ``Z`` per cell.

    Returns
    -------
    doc : TransitionFile
    arrays : dict of str -> ndarray (floats validated finite; ``"num/den"`` string arrays kept)

    Raises
    ------
    TransitionFileError
        Naming the file and the field, for anything missing, damaged or inconsistent.
    """
    directory = Path(directory)
    jpath, npath = directory / f"{stem}.json", directory / f"{stem}.npz"
    data = _read_json(jpath)
    if data.get("format") != FORMAT_NAME:
        raise _fail(jpath, f"field 'format' is {data.get('format')!r}, expected {FORMAT_NAME!r}")
    if data.get("version") in OLD_VERSIONS and not isinstance(data.get("version"), bool):
        raise _fail(jpath, f"field 'version' is {data['version']}: files before version 3 are no longer read "
                           f"(their margins are in other units); convert them with `{CONVERTER}`")
    if data.get("version") not in READ_VERSIONS or isinstance(data.get("version"), bool):
        raise _fail(jpath, f"field 'version' is {data.get('version')!r}, this tubejax reads versions "
                           f"{', '.join(map(str, READ_VERSIONS))}")
    doc = validate_document(TransitionFile, data, jpath)
    if not doc.npz_sha256:
        raise _fail(jpath, "field 'npz_sha256' is missing (every file records its npz's hash)")
    arrays = read_npz(jpath, npath, doc, "the evidence of the edges")
    _check_arrays(doc, arrays, npath)
    return doc, arrays


def validate_document(model, data: dict, jpath: Path, error: type[InputError] = TransitionFileError):
    """``data`` (the content of ``jpath``) validated as ``model``; else ``error`` naming the first five bad fields."""
    try:
        return model.model_validate(data)
    except pydantic.ValidationError as exc:
        problems = input_error(exc).problems
        raise error(f"{jpath}: " + "; ".join(f"field '{f}': {m}" for f, m in problems[:5])
                    + (f" (and {len(problems) - 5} more)" if len(problems) > 5 else "")) from None


def read_npz(jpath: Path, npath: Path, doc, what: str, error: type[InputError] = TransitionFileError) -> dict:
    """The arrays of ``npath`` (holding ``what``), the npz of the validated json ``doc`` read from ``jpath``; an
    ``error`` if it is missing or damaged, or its SHA-256 or ``format_version`` is not the json's."""
    if not npath.is_file():
        raise error(f"{npath}: no such file ({what})")
    if sha256_file(npath) != doc.npz_sha256:
        raise error(f"{npath}: its SHA-256 differs from {jpath.name}'s 'npz_sha256': the two files do not "
                    "belong together, or one was modified")
    try:
        with np.load(npath, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile, zlib.error) as exc:
        raise error(f"{npath}: cannot read the npz ({type(exc).__name__}: {exc}); the file is damaged or "
                    "truncated") from None
    fv = arrays.get("format_version")
    if fv is None or fv.shape != () or fv.dtype.kind not in "iu" or int(fv) != doc.version:
        raise error(f"{npath}: array 'format_version' is {None if fv is None else fv.tolist()!r}, expected "
                    f"{doc.version} (the version of {jpath.name})")
    return arrays


def _z_rows(z, k: int, n: int, default: int | None = None) -> int:
    """The vertex count a stored ``Z`` may have for a cell with ``k`` vertices: its own row count
    when the Z registry's rule allows it (:func:`~tubejax.model.zshape.kinds.z_vertex_count_problem`:
    in 2-D a multiple of ``k``, a chamfer ``Z``), else ``default`` (``k``)."""
    if isinstance(z, np.ndarray) and z.ndim == 2 and z_vertex_count_problem(z.shape[0], k, n) is None:
        return z.shape[0]
    return k if default is None else default


#: The npz arrays of the non-edges' evidence, after ``nonedge_`` (:meth:`tubejax.transitions.records.NonEdges.arrays`).
NONEDGE_ARRAYS = ("src", "dst", "L", "kind", "bound", "rep", "cert_ptr", "cert_rows", "cert_y")


def _check_arrays(doc: TransitionFile, arrays: dict, npath: Path) -> None:
    N = len(doc.cells)
    n = len(doc.cells[0].vertices[0])
    m = len(doc.system.B[0])
    names = evidence_names(doc.method)
    expected = {"format_version"}
    nz = []                                  # Z_i's vertex count: the cell's, or (2-D) a multiple of it
    for i, c in enumerate(doc.cells):
        expected.add(f"Z_{i}")
        rows = _z_rows(arrays.get(f"Z_{i}"), len(c.vertices), n)
        _check_npz_array(npath, arrays, f"Z_{i}", (rows, n))
        nz.append(rows)
    for k, e in enumerate(doc.edges):
        if not (e.src < N and e.dst < N):
            raise _fail(npath.with_suffix(".json"), f"field 'edges[{k}]': cell ids {e.src} -> {e.dst} "
                                                    f"outside [0, {N - 1}]")
        if e.src == e.dst:
            raise _fail(npath.with_suffix(".json"), f"field 'edges[{k}]': {e.src} -> {e.dst} is a self-pair, "
                                                    "which is not a transition (docs/math/tube-lp.md)")
        nv = nz[e.src]
        if f"edge_{k}_Z" in arrays:                # the pair's own Z (optional): its vertex count
            nv = _z_rows(arrays[f"edge_{k}_Z"], len(doc.cells[e.src].vertices), n, nv)
            expected.add(f"edge_{k}_Z")
            _check_npz_array(npath, arrays, f"edge_{k}_Z", (nv, n))
        shapes = {"p": (e.L, n), "eps": (e.L,), "u": (e.L, nv, m)}
        for name in names:
            expected.add(f"edge_{k}_{name}")
            _check_npz_array(npath, arrays, f"edge_{k}_{name}", shapes[name])
        exact = [f"edge_{k}_exact_{name}" for name in names]
        if any(key in arrays for key in exact):
            for key in exact:
                expected.add(key)
                _check_npz_array(npath, arrays, key, strings=True)
    if "nonedge_src" in arrays:                  # the evidence of the non-edges (tubejax.transitions.records)
        expected |= {f"nonedge_{name}" for name in NONEDGE_ARRAYS}
    extra = sorted(set(arrays) - expected)
    if extra:
        k_max = len(doc.edges) - 1
        raise _fail(npath, f"unexpected array {extra[0]!r}" + (f" and {len(extra) - 1} more" if len(extra) > 1 else "")
                    + f" (the json lists {len(doc.edges)} edges, ids 0..{k_max}, and {N} cells)")


def json_safe(obj):
    """``obj`` with NumPy scalars and arrays as Python values and non-finite floats as ``None``
    (JSON has no NaN or infinity), recursively through dicts, lists and tuples."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
