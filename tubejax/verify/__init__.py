"""Prove a saved transition system from its sources: ``python -m tubejax verify DIR``.

``verifier``
    :func:`~tubejax.verify.verifier.verify_directory`: read strictly, rebuild, re-check every edge's
    evidence and the non-edges (:class:`~tubejax.verify.verifier.VerifyReport`).
``completeness``
    ``verify --complete``: every non-edge's recorded evidence re-checked, or the instance re-solved.
``rho``
    The checks of the edges' ``rho_star`` (the critical disturbance of a radius analysis).
``sources``
    Rebuild a run's problem from its inputs record and compare it with the file's copies.
``claims``
    What a run's files claim beyond each edge's evidence (shard, ``metrics.json``), re-checked.
``run_config``
    The inputs record against the run's saved config (``stats.config``, ``.hydra/config.yaml``),
    and the problem the edges are proved for, in words.
``shard_merge``
    Merge the outputs of the shards of one run, each loaded checked against its sources.
``product_merge``
    Merge the shards of one product run (each joined its own source cells) into the unsharded product system.

Importing this package imports none of its modules; ``tj.verify`` stays the function
:func:`tubejax.api.verify`.
"""
