"""Prove a saved transition system from its sources: ``python -m tubejax verify DIR``.

``verifier`` (read strictly, rebuild, re-check every edge), ``completeness`` (``--complete``), ``rho``
(the edges' ``rho_star``), ``sources`` (rebuild and compare), ``claims`` (shard, ``metrics.json``),
``run_config`` (the saved config), ``shard_merge`` and ``product_merge`` (merge a run's shards).
Importing this package imports none of its modules; ``tj.verify`` stays :func:`tubejax.api.verify`.
"""
