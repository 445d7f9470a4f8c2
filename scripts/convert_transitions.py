"""Convert a transition system written in format version 1 or 2 to the current format.

    python scripts/convert_transitions.py OLD_RUN NEW_RUN [--stem transitions]

Files before format 3 measured each edge's margin per unit of the LP row's coefficients (``"coefficients"``);
tubejax now reads only versions 3 and later, whose margins are state-space distances (``"state"``;
docs/math/margins.md#state-space-distances). The converter reads the old pair ``<stem>.json`` / ``<stem>.npz``
(hash, arrays and fields checked as for any file), measures every edge's margin again from its stored evidence
with the rows scaled by their state-space normals, and writes the pair in the current format to ``NEW_RUN``.
Edges, horizons, evidence and the inputs record are kept; only the margins change units. A file that
demanded a margin (``min_margin > 0``) is refused: which instances reach it is a question in the old units,
so rerun it instead. ``python -m tubejax verify NEW_RUN`` proves the result from its sources as before.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from tubejax.errors import InputError
from tubejax.lp.evidence.verdict import evidence_margin
from tubejax.lp.declarations.openloop_lp import build_openloop_lp
from tubejax.lp.declarations.tube_lp import build_tube_lp
from tubejax.transitions.file_format import FORMAT_NAME, sha256_file
from tubejax.transitions.transition_system import TransitionSystem

#: The format versions this script converts.
OLD_VERSIONS = (1, 2)


def _as_version_3(old: Path, tmp: Path, stem: str) -> None:
    """Copy the old pair into ``tmp`` as a version-3 pair that states its margins' scaling (``"coefficients"``)."""
    jpath, npath = old / f"{stem}.json", old / f"{stem}.npz"
    try:
        doc = json.loads(jpath.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{jpath}: cannot read it as JSON ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != FORMAT_NAME:
        raise InputError(f"{jpath}: expected a {FORMAT_NAME!r} file")
    if doc.get("version") not in OLD_VERSIONS or isinstance(doc.get("version"), bool):
        raise InputError(f"{jpath}: field 'version' is {doc.get('version')!r}; this script converts versions "
                         f"{', '.join(map(str, OLD_VERSIONS))} (later ones load as they are)")
    if doc.get("npz_sha256") and (not npath.is_file() or sha256_file(npath) != doc["npz_sha256"]):
        raise InputError(f"{npath}: missing, or its SHA-256 differs from {jpath.name}'s 'npz_sha256'")
    if doc.get("min_margin", 0) != 0:
        raise InputError(f"{jpath}: min_margin is {doc['min_margin']!r} in the old units (per unit of the LP "
                         "coefficients); which instances reach it in state-space units is not known: rerun the "
                         "abstraction with this tubejax instead")
    try:
        with np.load(npath, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError) as exc:
        raise InputError(f"{npath}: cannot read the npz ({exc})") from None
    arrays["format_version"] = np.array(3)
    with open(tmp / f"{stem}.npz", "wb") as f:
        np.savez_compressed(f, **arrays)
    doc.update(version=3, margin_scaling="coefficients", npz_sha256=sha256_file(tmp / f"{stem}.npz"))
    (tmp / f"{stem}.json").write_text(json.dumps(doc))


def convert(old, new, stem: str = "transitions") -> TransitionSystem:
    """Convert the format-1/2 pair ``old/<stem>.*`` to the current format in ``new`` (see the module docstring).

    Raises
    ------
    InputError
        Naming the file: not a version 1 or 2 transitions file, a damaged pair, or ``min_margin > 0``.
    """
    old, new = Path(old), Path(new)
    with tempfile.TemporaryDirectory(prefix="tubejax-convert-") as tmp:
        _as_version_3(old, Path(tmp), stem)
        ts = TransitionSystem.load(tmp, stem)
    build = {"tube": build_tube_lp, "openloop": build_openloop_lp}.get(ts.method)
    edges = list(ts.edges)
    if build is not None:                                  # exact2d stores no evidence and no LP margin
        for k, prob in ts.problems():
            edges[k] = dataclasses.replace(edges[k], margin=float(evidence_margin(build(prob, scaling="state"),
                                                                                  ts.tubes[k])))
    ts.edges, ts.margin_scaling = edges, "state"
    ts.save(new, stem)
    return ts


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old", type=Path, help="directory of the version 1 or 2 files")
    parser.add_argument("new", type=Path, help="directory to write the converted files to")
    parser.add_argument("--stem", default="transitions")
    args = parser.parse_args(argv)
    try:
        ts = convert(args.old, args.new, args.stem)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"converted {ts.n_edges} edges to {args.new / (args.stem + '.json')} (margins in state-space units)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
