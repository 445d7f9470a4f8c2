"""Who wrote an output file: the tubejax version, the git commit and the command line
(docs/reference/formats.md#provenance), so a figure or table can be traced back to its code.

:func:`provenance` gives the fields, :func:`stamp` adds them to a JSON document (one object, or four
columns of a flat row such as ``metrics.json``). The git state is read once per process. Only the
standard library is used, so importing :mod:`tubejax` stays cheap.
"""

from __future__ import annotations

import functools
import shlex
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

__all__ = ["PROVENANCE_KEYS", "package_version", "git_state", "provenance", "stamp"]

#: The fields of a provenance record, in order.
PROVENANCE_KEYS = ("tubejax_version", "git_commit", "git_dirty", "command")

#: The directory holding the ``tubejax`` package (a checkout's root when run from source).
_SOURCE_ROOT = Path(__file__).resolve().parents[2]


def package_version() -> str:
    """The tubejax version: the installed distribution's, else ``pyproject.toml``'s beside the package.

    Returns
    -------
    str
        E.g. ``'0.1.0'``; ``'unknown'`` when neither is available.
    """
    try:
        return metadata.version("tubejax")
    except metadata.PackageNotFoundError:
        pass
    try:
        with open(_SOURCE_ROOT / "pyproject.toml", "rb") as f:
            return str(tomllib.load(f)["project"]["version"])
    except (OSError, KeyError, TypeError, tomllib.TOMLDecodeError):
        return "unknown"


def _git(root: Path, *args: str) -> str | None:
    """``git -C root ARGS`` stdout, or ``None`` when git fails or is missing."""
    try:
        out = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=10,
                             check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout if out.returncode == 0 else None


@functools.lru_cache(maxsize=8)
def git_state(root: str | Path | None = None) -> tuple[str | None, bool | None]:
    """The commit and dirtiness of the git checkout at ``root`` (default: tubejax's source tree).

    Only a checkout whose top level is ``root`` itself counts (``root/.git`` exists), so a
    package installed inside some other repository reports ``(None, None)``. Cached per
    process.

    Parameters
    ----------
    root : str or Path, optional
        The directory holding the ``tubejax`` package.

    Returns
    -------
    commit : str or None
        The ``HEAD`` commit, 40 hex digits.
    dirty : bool or None
        Whether tracked files differ from ``HEAD`` (index or work tree); ``None`` with no commit.
    """
    root = _SOURCE_ROOT if root is None else Path(root).resolve()
    if not (root / ".git").exists():               # a directory, or a file in a worktree
        return None, None
    head = _git(root, "rev-parse", "--verify", "HEAD")
    commit = head.strip() if head else ""
    if len(commit) != 40 or any(c not in "0123456789abcdef" for c in commit):
        return None, None
    status = _git(root, "status", "--porcelain", "--untracked-files=no")
    return commit, (None if status is None else bool(status.strip()))


def provenance(argv: list[str] | None = None) -> dict:
    """The provenance record of an output written now.

    Parameters
    ----------
    argv : list of str, optional
        The command line (default ``sys.argv``).

    Returns
    -------
    dict
        ``{"tubejax_version": str, "git_commit": str | None, "git_dirty": bool | None,
        "command": str}`` (JSON-safe; see the module docstring).
    """
    commit, dirty = git_state()
    args = [str(a) for a in (sys.argv if argv is None else argv)]
    return {"tubejax_version": package_version(), "git_commit": commit, "git_dirty": dirty,
            "command": shlex.join(args)}


def stamp(document, flat: bool = False):
    """``document`` with its provenance added (a copy; the input is not modified).

    Parameters
    ----------
    document : dict or any
        A JSON document. Anything but a dict is returned unchanged.
    flat : bool
        Add the fields of :func:`provenance` as top-level keys (a table row, e.g. ``metrics.json``)
        instead of one ``"provenance"`` object.

    Returns
    -------
    dict or any
        The document with ``"provenance"`` (or the flat keys) added; keys it already has are kept.
    """
    if not isinstance(document, dict):
        return document
    record = provenance()
    if flat:
        return {**document, **{k: v for k, v in record.items() if k not in document}}
    return document if "provenance" in document else {**document, "provenance": record}
