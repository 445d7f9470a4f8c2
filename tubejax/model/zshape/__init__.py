"""The tube cross-sections ``Z``: ``kinds`` (the fixed kinds by name, ``make_z``, the pairing with a
cell's points), ``params`` (the parametrised families of a learned ``Z`` and their invariants) and
``table`` (the ``learned_z.json`` file). Learning is an analysis (:mod:`tubejax.analyses.zshape`).
Nothing is imported here, so ``kinds`` does not pull in JAX (``params`` and ``table`` do).
"""
