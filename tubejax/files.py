"""Reading the files a user writes: bytes, SHA-256, UTF-8 text and strict YAML.

Every failure is the caller's :class:`~tubejax.errors.InputError` subclass with
the file named (and the line and column where there is one).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Type

import yaml

from .errors import InputError

__all__ = ["MAX_FILE_BYTES", "read_bytes", "sha256_hex", "decode_utf8", "load_yaml_strict", "user_path"]

#: Largest user file read (bytes): far above any real map, well below what would exhaust memory.
MAX_FILE_BYTES = 64 * 1024 * 1024


def sha256_hex(data: bytes) -> str:
    """SHA-256 of ``data`` as 64 lowercase hex digits."""
    return hashlib.sha256(data).hexdigest()


def read_bytes(path, what: str, error: Type[InputError] = InputError) -> bytes:
    """The bytes of the file ``path``; ``what`` (e.g. ``'grid map'``) goes into the messages.

    Raises
    ------
    error
        The file is missing, a directory, unreadable, or larger than :data:`MAX_FILE_BYTES`.
    """
    p = Path(path)
    try:
        size = p.stat().st_size
        if p.is_dir():
            raise error(f"{p}: cannot read the {what} (it is a directory, expected a file)")
        if size > MAX_FILE_BYTES:
            raise error(f"{p}: the {what} has {size} bytes, more than the limit of {MAX_FILE_BYTES}")
        return p.read_bytes()
    except OSError as exc:
        raise error(f"{p}: cannot read the {what} ({exc.strerror or exc})") from None


def decode_utf8(data: bytes, name: str, error: Type[InputError] = InputError) -> str:
    """``data`` decoded as UTF-8 (a leading BOM is dropped).

    Raises
    ------
    error
        Invalid UTF-8, with the file, line and column (1-based) of the first bad byte.
    """
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        head = data[:exc.start]
        line = head.count(b"\n") + 1
        column = exc.start - (head.rfind(b"\n") + 1) + 1
        raise error(f"{name}, line {line}, column {column}: not valid UTF-8 text (byte "
                    f"0x{data[exc.start]:02x}); save the file as UTF-8") from None


def user_path(value, name: str, roots=(), error: Type[InputError] = InputError) -> Path:
    """A path as a user typed it (an environment variable, an argument), found where they meant it.

    An absolute path is taken as it is. A relative one is looked for, in this order, in the current
    directory, in ``$PWD`` (the directory the command was typed in: a Jupyter kernel runs in the
    notebook's folder but inherits it) and in ``roots`` (e.g. the repository root, where the docs'
    commands are typed); the first place where it exists wins.

    Parameters
    ----------
    value : str or path
    name : str
        What the path was given as (e.g. ``'TUBEJAX_SWEEP_DIR'``), for the message.
    roots : iterable of paths
        Further directories to resolve a relative path from.

    Returns
    -------
    Path
        An existing path, absolute.

    Raises
    ------
    error
        ``value`` is empty or exists in none of those places (the message lists them).
    """
    text = str(value).strip()
    if not text:
        raise error(f"{name}: expected a path, got an empty value")
    p = Path(text).expanduser()
    if p.is_absolute():
        places = [p]
    else:
        bases = [Path.cwd(), *([Path(os.environ["PWD"])] if os.environ.get("PWD") else []), *map(Path, roots)]
        places = list(dict.fromkeys((b / p).resolve() for b in bases))
    found = next((q for q in places if q.exists()), None)
    if found is None:
        raise error(f"{name}: {text!r} does not exist (looked for {', '.join(map(str, places))})")
    return found.resolve()


class _StrictSafeLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that refuses a key repeated in one mapping (YAML 1.2 forbids it)."""


def _construct_mapping(loader: _StrictSafeLoader, node: yaml.MappingNode, deep: bool = False):
    seen: dict = {}
    for key_node, _ in node.value:
        if key_node.tag == "tag:yaml.org,2002:merge":      # '<<: *anchor' may be overridden
            continue
        key = loader.construct_object(key_node, deep=True)
        try:
            hash(key)
        except TypeError:
            raise yaml.constructor.ConstructorError(
                "while constructing a mapping", node.start_mark,
                f"found an unhashable key ({type(key).__name__})", key_node.start_mark) from None
        if key in seen:
            raise yaml.constructor.ConstructorError(
                "while constructing a mapping", node.start_mark,
                f"duplicate key {key!r} (first at line {seen[key].line + 1})", key_node.start_mark)
        seen[key] = key_node.start_mark
    return yaml.SafeLoader.construct_mapping(loader, node, deep=deep)


_StrictSafeLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)


def load_yaml_strict(text: str, name: str, error: Type[InputError] = InputError):
    """Parse YAML ``text`` safely, refusing duplicate keys.

    Raises
    ------
    error
        Invalid YAML or a duplicate key, with the file, line and column named.
    """
    try:
        return yaml.load(text, Loader=_StrictSafeLoader)  # noqa: S506 (a SafeLoader subclass)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f", line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise error(f"{name}{where}: invalid YAML ({problem})") from None
    except RecursionError:
        raise error(f"{name}: invalid YAML (nested too deeply)") from None
