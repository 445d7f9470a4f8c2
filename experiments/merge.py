"""Merge the shard outputs of a multirun into one transition system.

Usage
-----
python experiments/abstract.py -m hydra/launcher=parallel shard.count=3 'shard.index=range(3)' \\
    hydra.sweep.dir=outputs/sweep
python experiments/merge.py outputs/sweep            # -> outputs/sweep/merged/transitions.json|npz
python -m tubejax verify outputs/sweep/merged

Every ``transitions.json`` below ``SWEEP_DIR`` (``merged/`` excepted) is one shard's output
(``shard.count=K shard.index=k``); so is every ``product_transitions.json`` of a product run
(``product=true``), merged into ``merged/product_transitions.json|npz``
(:func:`tubejax.verify.product_merge.merge_product_shards`). The shards must come from the same inputs (files by SHA-256,
system, settings; only ``shard.index`` and ``memory_budget_mb`` may differ) and be complete:
a missing, duplicated or unfinished shard is refused with a message naming it (exit code 2).
The merged system equals the one an unsharded run computes (:func:`tubejax.verify.shard_merge.merge_shards`);
its inputs record is the unsharded run's (``shard.count=1``).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import ArgumentParser  # noqa: E402

__all__ = ["main", "shard_directories"]


def shard_directories(sweep: Path, out: Path) -> list[Path]:
    """The shard outputs below ``sweep`` (sorted); refuses unfinished ones, naming how to resume them."""
    from tubejax.errors import InputError
    from tubejax.abstraction.runstore import run_state

    unfinished = sorted({m.parent.parent for m in sweep.rglob("rounds/manifest.json")
                         if run_state(m.parent.parent) != "complete" and out not in m.parents})
    if unfinished:
        d = unfinished[0]
        raise InputError(f"{d}: this shard's run is unfinished; continue it with: python experiments/abstract.py "
                         f"{_overrides(d)}resume=true hydra.run.dir={d}"
                         + (f" (and {len(unfinished) - 1} more unfinished)" if len(unfinished) > 1 else ""))
    return sorted({p.parent for name in ("transitions.json", "product_transitions.json") for p in sweep.rglob(name)
                   if out not in p.parents and p.parent != out})


def merge_product(dirs: list[Path], out: Path):
    """Merge product shards (``product_transitions.json``, :func:`tubejax.verify.product_merge.merge_product_shards`)
    into ``out``; refuses a sweep that mixes product and joint-LP shards."""
    from tubejax.abstraction.product_store import save_product
    from tubejax.errors import InputError
    from tubejax.verify.product_merge import merge_product_shards

    joint = [d for d in dirs if not (d / "product_transitions.json").is_file()]
    if joint:
        raise InputError(f"{joint[0]}: a joint-LP shard (transitions.json) among product shards "
                         f"({dirs[0] if dirs[0] not in joint else [d for d in dirs if d not in joint][0]}); "
                         "shards of one run are all product runs or none")
    ps, record = merge_product_shards(dirs)
    jpath, npath = save_product(ps, out, record)
    return ps, jpath, npath


def _overrides(d: Path) -> str:
    """The Hydra overrides the job was started with (``.hydra/overrides.yaml``), as command-line text."""
    import yaml

    try:
        ov = yaml.safe_load((d / ".hydra" / "overrides.yaml").read_text())
    except (OSError, yaml.YAMLError):
        return "<the job's overrides> "
    return "".join(f"'{o}' " for o in ov if isinstance(o, str))


def main(argv=None) -> int:
    ap = ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sweep_dir", type=Path, help="a Hydra multirun directory holding one folder per shard")
    ap.add_argument("--out", type=Path, default=None, help="where to write (default: SWEEP_DIR/merged)")
    args = ap.parse_args(argv)
    if not args.sweep_dir.is_dir():
        print(f"error: sweep_dir {args.sweep_dir} is not a directory", file=sys.stderr)
        return 2
    out = (args.out or args.sweep_dir / "merged").resolve()
    from tubejax.errors import InputError
    from tubejax.verify.shard_merge import merge_shards

    try:
        dirs = shard_directories(args.sweep_dir.resolve(), out)
        if not dirs:
            raise InputError(f"{args.sweep_dir}: no transitions.json found (expected one folder per shard)")
        if any((d / "product_transitions.json").is_file() for d in dirs):
            ts, jpath, npath = merge_product(dirs, out)
        else:
            ts = merge_shards(dirs)
    except (InputError, OSError) as exc:         # MergeError, TransitionFileError, a changed source file
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if hasattr(ts, "structure"):                     # a product system: already written
        print(f"merged {len(dirs)} product shards: {ts.n_cells} cells, {ts.n_edges} edges")
        print(f"wrote {jpath}\n      {npath}")
        return 0
    jpath, npath = ts.save(out, "transitions")
    if (dirs[0] / "learned_z.json").is_file():       # zshape=learned*: the learned Z travels with the merged run
        (out / "learned_z.json").write_bytes((dirs[0] / "learned_z.json").read_bytes())
    print(f"merged {len(dirs)} shards: {ts.n_cells} cells, {ts.n_edges} edges")
    print(f"wrote {jpath}\n      {npath}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
