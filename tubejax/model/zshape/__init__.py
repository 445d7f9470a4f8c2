"""The tube cross-sections ``Z``: the geometry each pair's tubes are built on.

``kinds``
    The fixed kinds by name (:data:`~tubejax.model.zshape.kinds.ZKINDS`: ``box``, ``diamond``,
    ``cell``, ``regular``, ``chamfer``), :func:`~tubejax.model.zshape.kinds.make_z`, the
    pairing of ``Z``'s vertices with a cell's points
    (:func:`~tubejax.model.zshape.kinds.source_points`) and the hook the learned kinds read
    (``ACTIVE_Z_TABLE``).
``params``
    Parametrised families of a learned ``Z`` (2-D polygons, n-D parallelotopes), their
    invariants and :func:`~tubejax.model.zshape.params.polytope_from_z`, the checked ``Z``.
``table``
    The ``learned_z.json`` file (:class:`~tubejax.model.zshape.table.ZTable`,
    :func:`~tubejax.model.zshape.table.load_z_table`, :func:`~tubejax.model.zshape.table.use_z_table`)
    and the cross-sections of a run from a table
    (:func:`~tubejax.model.zshape.table.assignment_from_table`).

Learning a ``Z`` (gradients through the LP layer) is an analysis: :mod:`tubejax.analyses.zshape`.
Nothing is imported here, so ``kinds`` does not pull in JAX (``params`` and ``table`` do).
"""
