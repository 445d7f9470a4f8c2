"""The on-disk state of a run of Algorithm 2: settled instances, step by step, for resuming.

``RUN_DIR/rounds/manifest.json`` (the run's identity and its finished steps) and one npz per
finished *step* (a chunk of a round, or the HiGHS confirmations of a sweep), laid out as in
docs/reference/formats.md#run-directories. A step lists *facts*: pair ``k`` solved at horizon ``L``
with a status of :data:`STATUSES`, and for an edge its evidence. A fact is a deterministic function
of ``(k, L)``, so replaying the files in order rebuilds the exact
:class:`~tubejax.abstraction.schedule.PairSchedule`. Writes are atomic (temporary file, fsync,
rename; then the manifest); a file the manifest does not list is removed on resume, listed files'
SHA-256 are checked on reading, and a resume must match the manifest's ``identity``.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..errors import InputError
from ..lp.evidence import QArray
from ..lp.evidence.registry import FORMULATIONS
from ..transitions.records import Edge, pack as pack_refutations, unpack as unpack_refutations
from ..transitions.file_format import atomic_write, evidence_names, json_safe, sha256_file

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "STATUSES", "RunStoreError", "Facts", "RunStore", "run_state",
           "record_differences", "candidates_fingerprint"]

FORMAT_NAME = "tubejax.rounds"
#: Version 2: margins are state-space distances (docs/math/margins.md#state-space-distances); a
#: version-1 run (margins per unit of the LP coefficients) cannot be resumed, only rerun.
FORMAT_VERSION = 2
ROUNDS = "rounds"
MANIFEST = "manifest.json"
#: Fact statuses, in the order of their codes in the step files.
STATUSES = ("infeasible", "unconfirmed", "edge")
#: Files of a finished run (written by the apps beside ``rounds/``).
FINAL_FILES = ("transitions.json", "transitions.npz", "metrics.json", "product_transitions.json", "product_transitions.npz")
#: The file whose presence (with a complete manifest) makes a run complete: a joint-LP or a product run's.
FINAL_JSON = ("transitions.json", "product_transitions.json")


class RunStoreError(InputError):
    """A run directory's round files are missing, damaged, inconsistent or of another run."""


class Facts(NamedTuple):
    """Instances settled in one step.

    Attributes
    ----------
    pair : ndarray of int, shape (F,)      candidate pair index
    L : ndarray of int, shape (F,)         horizon
    status : list of str, length F         one of :data:`STATUSES`
    provenance : list of str, length F
    edges : list of Edge                   the facts with status ``'edge'``, in fact order
    tubes : list                           their evidence (Tube, OpenLoopPlan or None)
    src, dst : ndarray of int, shape (F,)  the pairs' cells as written (read back for cross-checking)
    refutations : list, length F, or None  each refused fact's ``Refutation`` (``None``: an edge)
    pending : list of (int, int, str) or None
        Likely edges (pair, horizon, provenance) still being confirmed when the step was written: a
        resumed run confirms the last step's the same way, to the same provenances.
    held : list of int or None
        Pairs whose likely edge HiGHS refused in this sweep (later horizons wait for the next).
    sweep : int or None
        The sweep over the horizons the step belongs to (1: the first).
    """

    pair: np.ndarray
    L: np.ndarray
    status: list
    provenance: list
    edges: list
    tubes: list
    src: np.ndarray | None = None
    dst: np.ndarray | None = None
    refutations: list | None = None
    pending: list | None = None
    held: list | None = None
    sweep: int | None = None


def candidates_fingerprint(cand, L_max: int, method: str) -> dict:
    """What identifies the instances of a run: SHA-256 over pairs, horizons and obstacle cases."""
    h = hashlib.sha256()
    for a in (cand.src, cand.dst, cand.keep, cand.obstacle):
        a = np.ascontiguousarray(a)
        h.update(str((a.dtype.str, a.shape)).encode())
        h.update(a.tobytes())
    return {"sha256": h.hexdigest(), "n_pairs": int(len(cand.src)), "n_instances": int(cand.keep.sum()),
            "L_max": int(L_max), "method": str(method)}


def record_differences(old, new, prefix: str = "") -> list[tuple[str, object, object]]:
    """``(dotted path, old value, new value)`` for every leaf where two JSON-like records differ."""
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for k in sorted(set(old) | set(new), key=str):
            path = f"{prefix}.{k}" if prefix else str(k)
            if k not in old or k not in new:
                out.append((path, old.get(k, "<absent>"), new.get(k, "<absent>")))
            else:
                out += record_differences(old[k], new[k], path)
        return out
    if isinstance(old, list) and isinstance(new, list) and len(old) == len(new):
        return [d for k, (a, b) in enumerate(zip(old, new)) for d in record_differences(a, b, f"{prefix}[{k}]")]
    return [] if old == new else [(prefix or "record", old, new)]


def run_state(directory) -> str:
    """``'empty'`` (no run here), ``'partial'`` (started, not finished) or ``'complete'`` (a final json
    of :data:`FINAL_JSON`, and a manifest that says so or no round files at all)."""
    d = Path(directory)
    man = d / ROUNDS / MANIFEST
    if man.exists():
        try:
            status = json.loads(man.read_text()).get("status")
        except (OSError, ValueError, AttributeError):
            return "partial"
        final = any((d / f).exists() for f in FINAL_JSON)
        return "complete" if status == "complete" and final else "partial"
    if any((d / f).exists() for f in FINAL_JSON):
        return "complete"
    if (d / ROUNDS).exists() or any((d / f).exists() for f in FINAL_FILES):
        return "partial"
    return "empty"


class RunStore:
    """The round files (``rounds/``) of one run directory (see the module docstring)."""

    def __init__(self, directory):
        self.directory = Path(directory)
        self.rounds = self.directory / ROUNDS
        self.manifest_path = self.rounds / MANIFEST
        self._manifest: dict | None = None

    def exists(self) -> bool:
        return self.manifest_path.exists()

    def create(self, identity: dict) -> None:
        """Start a new run here with ``identity`` (JSON-safe); refuses if one exists."""
        if self.exists():
            raise RunStoreError(f"{self.manifest_path}: a run was already started here")
        self.rounds.mkdir(parents=True, exist_ok=True)
        self._manifest = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "status": "running",
                          "identity": json_safe(identity), "candidates": None, "steps": []}
        self._write_manifest()

    def identity(self) -> dict:
        """The identity the run was created with."""
        return self.manifest()["identity"]

    def clear(self) -> None:
        """Delete the round files and the final files of a run (``overwrite``)."""
        shutil.rmtree(self.rounds, ignore_errors=True)
        for name in FINAL_FILES:
            (self.directory / name).unlink(missing_ok=True)
        self._manifest = None

    def manifest(self) -> dict:
        """The manifest, read and validated once."""
        if self._manifest is None:
            self._manifest = self._read_manifest()
        return self._manifest

    def _read_manifest(self) -> dict:
        p = self.manifest_path
        try:
            m = json.loads(p.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise RunStoreError(f"{p}: no such file (no run was started in {self.directory})") from None
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            raise RunStoreError(f"{p}: cannot read the manifest ({str(exc).splitlines()[0]})") from None
        if not isinstance(m, dict) or m.get("format") != FORMAT_NAME:
            raise RunStoreError(f"{p}: field 'format' is {m.get('format') if isinstance(m, dict) else m!r}, "
                                f"expected {FORMAT_NAME!r}")
        if m.get("version") != FORMAT_VERSION:
            raise RunStoreError(f"{p}: field 'version' is {m.get('version')!r}, this tubejax reads version "
                                f"{FORMAT_VERSION} (a run of another version cannot be resumed: start it "
                                f"again in a new directory)")
        for key, kind in (("status", str), ("identity", dict), ("steps", list)):
            if not isinstance(m.get(key), kind):
                raise RunStoreError(f"{p}: field {key!r} is missing or not a {kind.__name__}")
        for k, s in enumerate(m["steps"]):
            ok = (isinstance(s, dict) and isinstance(s.get("file"), str) and "/" not in s["file"]
                  and isinstance(s.get("sha256"), str) and isinstance(s.get("n_facts"), int))
            if not ok:
                raise RunStoreError(f"{p}: field 'steps[{k}]' is malformed (expected file, sha256, n_facts)")
        return m

    def _write_manifest(self) -> None:
        text = json.dumps(self._manifest, indent=1, allow_nan=False).encode()
        atomic_write(self.manifest_path, lambda f: f.write(text))

    def bind(self, fingerprint: dict) -> list[tuple[str, Facts]]:
        """Check (or, on a new run, record) the candidates fingerprint; return ``(file name, facts)`` of
        every committed step, in order; files the manifest does not list (never committed) are removed.
        A ``RunStoreError`` when the instances differ from the run's or a step file is missing or damaged."""
        m = self.manifest()
        if m["candidates"] is None:
            if m["steps"]:
                raise RunStoreError(f"{self.manifest_path}: steps are listed but no candidates fingerprint")
            m["candidates"] = json_safe(fingerprint)
            self._write_manifest()
        elif m["candidates"] != json_safe(fingerprint):
            diff = "; ".join(f"{p}: {a!r} in the run, {b!r} now"
                             for p, a, b in record_differences(m["candidates"], json_safe(fingerprint)))
            raise RunStoreError(f"{self.manifest_path}: the candidate instances differ from the interrupted "
                                f"run's ({diff}); was it started by another tubejax version?")
        listed = {s["file"] for s in m["steps"]}
        for f in self.rounds.iterdir():
            if f.name != MANIFEST and f.name not in listed:
                f.unlink()
        return [(s["file"], self._read_step(s, fingerprint)) for s in m["steps"]]

    def append(self, L, facts: Facts, src, dst, method: str, info: dict | None = None) -> Path:
        """Write one step's facts (``src``, ``dst``: the candidates' arrays) and commit it in the manifest."""
        m = self.manifest()
        seq = len(m["steps"]) + 1
        name = f"{seq:05d}-L{int(L):02d}.npz" if L is not None else f"{seq:05d}-confirm.npz"
        path = self.rounds / name
        arrays = _fact_arrays(facts, src, dst, method)
        atomic_write(path, lambda f: np.savez(f, **arrays))
        entry = {"file": name, "sha256": sha256_file(path), "L": None if L is None else int(L),
                 "n_facts": len(facts.pair), "n_edges": len(facts.edges), **json_safe(info or {})}
        m["steps"].append(entry)
        self._write_manifest()
        return path

    def mark_complete(self) -> None:
        """Record that the final files were written."""
        self.manifest()["status"] = "complete"
        self._write_manifest()

    def _read_step(self, entry: dict, fingerprint: dict) -> Facts:
        path = self.rounds / entry["file"]
        if not path.exists():
            raise RunStoreError(f"{path}: no such file (listed in {self.manifest_path.name})")
        if sha256_file(path) != entry["sha256"]:
            raise RunStoreError(f"{path}: its SHA-256 differs from the one in {self.manifest_path.name}: "
                                "the file was modified or damaged")
        try:
            with np.load(path, allow_pickle=False) as z:
                arr = {k: z[k] for k in z.files}
            return _facts_from_arrays(arr, fingerprint["method"], entry["n_facts"])
        except (OSError, ValueError, KeyError, IndexError) as exc:
            raise RunStoreError(f"{path}: cannot read the step ({str(exc).splitlines()[0]})") from None


def _fact_arrays(facts: Facts, src, dst, method: str) -> dict:
    pair = np.asarray(facts.pair, dtype=np.int64)
    names = sorted(set(facts.provenance))
    arrays = {
        "format_version": np.array(FORMAT_VERSION), "pair": pair,
        "src": np.asarray(src, dtype=np.int64)[pair], "dst": np.asarray(dst, dtype=np.int64)[pair],
        "L": np.asarray(facts.L, dtype=np.int64),
        "status": np.array([STATUSES.index(s) for s in facts.status], dtype=np.int8),
        "provenance_names": np.array(names, dtype=str),
        "provenance": np.array([names.index(p) for p in facts.provenance], dtype=np.int16),
        "edge_margin": np.array([e.margin for e in facts.edges], dtype=float),
        "edge_proof": np.array([e.proof or "" for e in facts.edges], dtype="U5"),
        "edge_violation": np.array([np.nan if e.violation is None else e.violation for e in facts.edges],
                                   dtype=float),
        **pack_refutations(facts.refutations or [None] * len(pair), "ref_"),
        "pending_pair": np.array([k for k, _, _ in facts.pending or []], dtype=np.int64),
        "pending_L": np.array([L for _, L, _ in facts.pending or []], dtype=np.int64),
        "pending_provenance": np.array([p for _, _, p in facts.pending or []], dtype=str),
        "held_pair": np.array(facts.held or [], dtype=np.int64),
        "sweep": np.array(-1 if facts.sweep is None else int(facts.sweep)),
    }
    for k, (e, t) in enumerate(zip(facts.edges, facts.tubes)):
        if t is not None and evidence_names(method):
            for name, value in t._asdict().items():
                arrays[f"edge_{k}_{name}"] = np.asarray(value, dtype=float)
        if e.exact is not None:
            for name, value in e.exact._asdict().items():
                arrays[f"edge_{k}_exact_{name}"] = value.to_strings()
    return arrays


def _facts_from_arrays(arr: dict, method: str, n_facts: int) -> Facts:
    if int(arr["format_version"]) != FORMAT_VERSION:
        raise ValueError(f"format_version {int(arr['format_version'])}, expected {FORMAT_VERSION}")
    pair, L = arr["pair"].astype(np.int64), arr["L"].astype(np.int64)
    if not (len(pair) == len(L) == len(arr["status"]) == len(arr["provenance"]) == n_facts):
        raise ValueError(f"the fact arrays do not all hold the {n_facts} facts the manifest lists")
    status = [STATUSES[int(s)] for s in arr["status"]]
    names = arr["provenance_names"].tolist()
    prov = [names[int(p)] for p in arr["provenance"]]
    is_edge = [k for k, s in enumerate(status) if s == "edge"]
    if len(is_edge) != len(arr["edge_margin"]):
        raise ValueError(f"{len(is_edge)} edge facts but {len(arr['edge_margin'])} edge margins")
    edges, tubes = [], []
    ev = evidence_names(method)
    for e, k in enumerate(is_edge):
        proof = str(arr["edge_proof"][e]) or None
        viol = float(arr["edge_violation"][e])
        exact = None
        if f"edge_{e}_exact_{ev[0] if ev else 'u'}" in arr:
            vals = [QArray.from_strings(arr[f"edge_{e}_exact_{n}"]) for n in ev]
            exact = FORMULATIONS[method].exact_type(*vals)
        edges.append(Edge(int(arr["src"][k]), int(arr["dst"][k]), int(L[k]), float(arr["edge_margin"][e]),
                          prov[k], proof, None if np.isnan(viol) else viol, exact))
        tubes.append(_evidence(arr, e, method))
    refs = unpack_refutations(arr, "ref_", n_facts) if "ref_kind" in arr else [None] * n_facts
    pending = None
    if "pending_pair" in arr:
        pp, pl, pv = arr["pending_pair"], arr["pending_L"], arr["pending_provenance"]
        if not (pp.shape == pl.shape == pv.shape and pp.ndim == 1):
            raise ValueError("pending_pair/pending_L/pending_provenance: expected three equal 1-D arrays")
        pending = [(int(k), int(h), str(p)) for k, h, p in zip(pp, pl, pv)]
    held = [int(k) for k in arr["held_pair"]] if "held_pair" in arr else None
    sweep = int(arr["sweep"]) if "sweep" in arr and int(arr["sweep"]) >= 0 else None
    return Facts(pair, L, status, prov, edges, tubes, arr["src"].astype(np.int64), arr["dst"].astype(np.int64),
                 refs, pending, held, sweep)


def _evidence(arr: dict, e: int, method: str):
    form = FORMULATIONS.get(method)
    if form is None or form.evidence_type is None:
        return None
    return form.evidence_type(*(arr[f"edge_{e}_{n}"] for n in form.evidence_names))
