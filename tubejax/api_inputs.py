"""Workspaces and systems for the Python API (:mod:`tubejax.api`), each with its inputs record
(:class:`~tubejax.inputs.ProblemInputs`), so a system built from Python is rebuilt and verified from
its sources like one built by ``experiments/abstract.py``.

A workspace file is recorded by path and SHA-256; a workspace given as text is kept as a file named
after its SHA-256 until the system is saved beside it; a :func:`box_grid` is recorded whole.
"""

from __future__ import annotations

import atexit
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import InputError, InputModelError
from .files import sha256_hex
from .model.geometry import Ball, Polytope
from .inputs import BoxGridSource, GridMapSource, PolygonFileSource, validate_section
from .model.system import LinearSystem, box_input_set, one_norm_input_set
from .model.workspace import CellDecomposition

__all__ = ["Workspace", "grid_map", "polygon_workspace", "box_grid", "paper_system", "system_entries",
           "same_set"]


@dataclass(frozen=True, eq=False)
class Workspace:
    """A cell decomposition and the inputs-record entry it was made from.

    Make one with :func:`grid_map`, :func:`polygon_workspace` or :func:`box_grid`.

    Attributes
    ----------
    decomposition : CellDecomposition
        The cells (``n_cells`` convex polytopes), their region labels and the obstacles.
    source : dict
        The ``workspace`` entry of the inputs record (a file by path, absolute path and
        SHA-256, or a box grid's fields).
    files : tuple of (str, bytes)
        Files written beside a saved transition system (a workspace given as text), by name.
    """

    decomposition: CellDecomposition
    source: dict
    files: tuple = ()

    @property
    def n_cells(self) -> int:
        """Number of cells ``N``."""
        return self.decomposition.n_cells

    @property
    def labels(self) -> tuple:
        """Region label of each cell (``None`` for an unlabelled one), length ``N``."""
        return self.decomposition.labels

    @property
    def name(self) -> str:
        """Where the workspace came from (a file, or the name given)."""
        return self.decomposition.name

    def __repr__(self) -> str:
        regions = sorted({str(l) for l in self.labels if l is not None})
        return (f"Workspace({self.name!r}, {self.n_cells} cells, {self.decomposition.dim}-D, "
                f"regions {regions})")


_SESSION: list = []


def _session_dir() -> Path:
    """A temporary directory of this process for sources given as text (removed at exit)."""
    if not _SESSION:
        d = Path(tempfile.mkdtemp(prefix="tubejax-sources-"))
        atexit.register(shutil.rmtree, d, True)
        _SESSION.append(d)
    return _SESSION[0]


def _is_path(value, arg: str) -> bool:
    """A path is a ``Path`` or a one-line string; text has a line break."""
    if isinstance(value, Path):
        return True
    if not isinstance(value, str):
        raise InputError(f"{arg}: expected a file path or the file's text (a string), got {type(value).__name__}")
    return "\n" not in value


def _file_entry(value, stem: str, suffix: str) -> tuple[dict, tuple]:
    """The record's file entry for ``value`` (a path, or text kept as ``<stem>-<sha12><suffix>``); ``stem``
    is also the argument's name in errors."""
    if _is_path(value, stem):
        return {"path": str(value)}, ()
    data = value.encode("utf-8")
    name = f"{stem}-{sha256_hex(data)[:12]}{suffix}"
    path = _session_dir() / name
    if not path.is_file():
        path.write_bytes(data)
    return {"path": name, "resolved": str(path)}, ((name, data),)


def _validated(model, data: dict):
    return validate_section(model, data, "workspace", rename=lambda f: f.replace(".map_file", "").replace(".file", ""))


#: The kind and the file's field of each file source.
_FILE_SOURCES = {GridMapSource: ("grid", "map_file"), PolygonFileSource: ("polygon", "file")}


def _file_workspace(source, value, name: str | None, stem: str, suffix: str) -> Workspace:
    """The workspace of ``source``'s file ``value`` (a path, or text kept as ``<stem>-<sha12><suffix>``)."""
    kind, field = _FILE_SOURCES[source]
    entry, files = _file_entry(value, stem, suffix)
    model = _validated(source, {"kind": kind, field: entry})
    decomp = model.build(name=name or (Path(entry["path"]).stem if files else None))
    return Workspace(decomp, model.model_dump(mode="json"), files)


def grid_map(map, *, name: str | None = None) -> Workspace:
    """A grid-map workspace (docs/reference/formats.md#grid-map) from a file or from its text; a map
    with layers separated by lines ``---`` is a 3-D voxel map (docs/reference/formats.md#voxel-map).

    Parameters
    ----------
    map : str or Path
        A path (a ``Path``, or a string without a line break) or the map's text (a string with
        at least one line break, e.g. ``"1..\\n.#.\\n..2\\n"``): one line per row, ``#``
        obstacle, ``.`` free, ``0-9A-Za-z`` a free cell of that region.
    name : str, optional
        The workspace's name (default: the file's absolute path, or ``map-<sha12>`` for text).

    Returns
    -------
    Workspace
        Recorded by path and SHA-256; text is saved with the transition system as
        ``map-<sha12>.txt`` (see the module docstring).

    Raises
    ------
    InputError
        A missing or unreadable file, or a malformed map (naming the line and column).
    """
    return _file_workspace(GridMapSource, map, name, "map", ".txt")


def polygon_workspace(workspace, *, name: str | None = None) -> Workspace:
    """A polygon workspace (YAML: ``boundary``, ``obstacles``, ``regions``, ``max_area``), triangulated.

    Parameters
    ----------
    workspace : str or Path
        A path (a ``Path``, or a string without a line break) or the YAML text.
    name : str, optional
        The workspace's name (default: the file's absolute path, or ``workspace-<sha12>``).

    Returns
    -------
    Workspace
        Triangle cells (constrained Delaunay); text is saved as ``workspace-<sha12>.yaml``.

    Raises
    ------
    InputError
        A missing file, bad YAML, or bad fields (naming the line and field).
    """
    return _file_workspace(PolygonFileSource, workspace, name, "workspace", ".yaml")


def _floats(value, arg: str):
    """``value`` as (nested) lists of floats, for the model to check; ``arg`` names it in errors."""
    try:
        return np.asarray(value, float).tolist()
    except (TypeError, ValueError):
        raise InputError(f"{arg}: expected numbers (a list of coordinates), got {value!r}") from None


def box_grid(lower, upper, divisions, *, obstacles=(), labels=None, name: str = "box grid") -> Workspace:
    """A uniform box grid over ``[lower, upper]`` in ``R^n`` (:func:`tubejax.model.workspace.box_grid`).

    Parameters
    ----------
    lower, upper : array_like, shape (n,)
    divisions : int or sequence of int, shape (n,)
        Boxes per dimension.
    obstacles : sequence of (lower, upper)
        Obstacle boxes; the cells meeting one are removed.
    labels : dict, optional
        ``{label: (lower, upper)}``: cells inside that box carry the label.
    name : str

    Returns
    -------
    Workspace
        Recorded with all its fields (no file).

    Raises
    ------
    InputError
        Bad corners, divisions or boxes (naming the field).
    """
    def plain(d):                                   # NumPy integers as Python ints; anything else as given
        return int(d) if isinstance(d, np.integer) else d

    div = [plain(d) for d in divisions] if isinstance(divisions, (list, tuple, np.ndarray)) else plain(divisions)
    data = {"kind": "boxgrid", "name": str(name), "lower": _floats(lower, "lower"), "upper": _floats(upper, "upper"),
            "divisions": div, "obstacles": [_floats(b, f"obstacles[{k}]") for k, b in enumerate(obstacles)],
            "labels": {str(k): _floats(v, f"labels[{k!r}]") for k, v in (labels or {}).items()}}
    model = _validated(BoxGridSource, data)
    return Workspace(model.build(), model.model_dump(mode="json"))


def _as_workspace(workspace) -> Workspace:
    if isinstance(workspace, Workspace):
        return workspace
    if isinstance(workspace, (str, Path)):
        text_or_path = str(workspace)
        yaml = "\n" not in text_or_path and Path(text_or_path).suffix.lower() in (".yaml", ".yml")
        return polygon_workspace(workspace) if yaml else grid_map(workspace)
    raise InputError(f"workspace: expected a tj.Workspace (tj.grid_map, tj.polygon_workspace, tj.box_grid) or a "
                     f"map file's path, got {type(workspace).__name__}; a bare CellDecomposition has no source "
                     f"to record, so a saved system could not be verified from it")


def paper_system(radius: float = 0.2, *, u_set: str = "box") -> LinearSystem:
    """The paper's point mass ``x+ = x + 0.5 u + w`` (Section V; docs/math/tube-lp.md#paper-slips, slip 3).

    Parameters
    ----------
    radius : float
        ``W`` is the 2-norm ball of this radius (the paper: 0.2).
    u_set : {'box', 'one_norm'}
        ``U = {|u_1| <= 1, |u_2| <= 1}`` (the default) or ``{|u_1| + |u_2| <= 1}``.

    Returns
    -------
    LinearSystem
        ``A = I``, ``B = 0.5 I`` (2 x 2).

    Raises
    ------
    InputError
        A negative or non-finite radius, or an unknown ``u_set``.
    """
    if u_set not in ("box", "one_norm"):
        raise InputError(f"u_set: expected 'box' or 'one_norm', got {u_set!r}")
    if isinstance(radius, bool) or not isinstance(radius, (int, float, np.floating)) or not 0 <= radius < np.inf:
        raise InputError(f"radius: expected a finite number >= 0, got {radius!r}")
    U = box_input_set(1.0, 2) if u_set == "box" else one_norm_input_set(1.0, 2)
    return LinearSystem(A=np.eye(2), B=0.5 * np.eye(2), U=U, W=Ball(2, float(radius)))


def _u_entry(U: Polytope) -> dict:
    lo, hi = U.bounding_box()
    m = U.dim
    if np.array_equal(lo, -hi) and _same_points(U.vertices, Polytope.box(lo, hi).vertices):
        return {"kind": "box", "bound": float(hi[0]) if np.all(hi == hi[0]) else hi.tolist()}
    r = float(np.max(np.abs(U.vertices)))
    if _same_points(U.vertices, np.vstack([r * np.eye(m), -r * np.eye(m)])):
        return {"kind": "one_norm", "radius": r}
    return {"kind": "polytope", "vertices": U.vertices.tolist()}


def _w_entry(W) -> dict:
    if isinstance(W, Ball):
        return {"kind": "ball", "radius": float(W.radius)}
    lo, hi = W.bounding_box()
    if np.array_equal(lo, -hi) and np.all(hi == hi[0]) and hi[0] > 0 \
            and _same_points(W.vertices, Polytope.box(lo, hi).vertices):
        return {"kind": "box", "half_width": float(hi[0])}
    return {"kind": "polytope", "vertices": W.vertices.tolist()}


def system_entries(system: LinearSystem) -> tuple[dict, dict]:
    """The inputs record's ``system`` and ``disturbance`` entries of ``system``.

    Parameters
    ----------
    system : LinearSystem

    Returns
    -------
    system_entry : dict
        ``{"A", "B", "U"}``, ``U`` a box (``bound``), a 1-norm ball (``radius``) or a polytope
        (``vertices``), and each state constraint the system sets as its record (``{"H", "h"}``).
    disturbance_entry : dict
        A ball (``radius``), a box (``half_width``) or a polytope (``vertices``).

    Raises
    ------
    InputError
        ``system`` is not a :class:`~tubejax.model.system.LinearSystem`.
    """
    if not isinstance(system, LinearSystem):
        raise InputError(f"system: expected a tubejax LinearSystem (e.g. tj.LinearSystem(A=A, B=B, U=U, W=W) or "
                         f"tj.paper_system()), got {type(system).__name__}")
    constraints = {name: S.record() for name, S in system.state_constraints.items()}
    return ({"A": system.A.tolist(), "B": system.B.tolist(), "U": _u_entry(system.U), **constraints},
            _w_entry(system.W))


def _same_points(a, b) -> bool:
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape:
        return False
    return bool(np.array_equal(a[np.lexsort(a.T[::-1])], b[np.lexsort(b.T[::-1])]))


def same_set(a, b) -> bool:
    """Whether two sets of :mod:`tubejax.model.geometry` are given by the same data (a ball's radius,
    a polytope's vertices in any order)."""
    if isinstance(a, Ball) or isinstance(b, Ball):
        return isinstance(a, Ball) and isinstance(b, Ball) and a.dim == b.dim and a.radius == b.radius
    return _same_points(a.vertices, b.vertices)


#: Argument names of :func:`~tubejax.api.abstract` for the fields of the inputs record, in error messages.
_ARGUMENTS = (("abstraction.solver.name", "solver"), ("abstraction.solver.", "solver_options."),
              ("abstraction.", ""), ("zshape.kind", "zshape"), ("zshape.scale", "z_scale"),
              ("zshape.file", "z_file"), ("disturbance", "system.W"))


def _argument_error(exc: InputModelError) -> InputModelError:
    def rename(path: str) -> str:
        for model, arg in _ARGUMENTS:
            if path.startswith(model):
                return arg + path[len(model):]
        return path
    return InputModelError([(rename(f), m) for f, m in exc.problems])
