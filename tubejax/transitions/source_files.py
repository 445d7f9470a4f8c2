"""A transition system that saves, beside its own files, the sources it was given as text:
:class:`SavesSources` writes a workspace given to :func:`tubejax.api.abstract` as text beside the
transitions files (and points the inputs record there), so the saved system verifies from its sources.
"""

from __future__ import annotations

import copy
from pathlib import Path

from .transition_system import TransitionSystem

__all__ = ["SavesSources"]


class SavesSources(TransitionSystem):
    """A transition system whose workspace was given as text: :meth:`save` writes that text too."""

    source_files: tuple = ()

    @classmethod
    def of(cls, ts: TransitionSystem, files) -> "SavesSources":
        """A shallow copy of ``ts`` that saves ``files`` (``(name, bytes)`` pairs) with it."""
        out = copy.copy(ts)
        out.__class__ = cls
        out.source_files = tuple(files)
        return out

    def write_sources(self, directory) -> None:
        """Write the workspace text (``map-<sha12>.txt``) into ``directory`` and point the inputs record there."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        ws = dict((self.inputs or {}).get("workspace") or {})
        for name, data in self.source_files:
            target = directory / name
            if not (target.is_file() and target.read_bytes() == data):
                tmp = target.with_name(name + ".tmp")
                tmp.write_bytes(data)
                tmp.replace(target)
            for key in ("map_file", "file"):
                if isinstance(ws.get(key), dict) and ws[key].get("path") == name:
                    ws[key] = {**ws[key], "resolved": str(target.resolve())}
        if self.inputs is not None:
            self.inputs = {**self.inputs, "workspace": ws}

    def save(self, directory, stem: str = "transitions") -> tuple[Path, Path]:
        """Write the workspace text (``map-<sha12>.txt``) into ``directory``, then the transitions files,
        whose inputs record names that copy (see :meth:`TransitionSystem.save`)."""
        self.write_sources(directory)
        return super().save(directory, stem)
