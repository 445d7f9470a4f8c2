"""The model, the bottom layer: ``geometry/`` (polytopes, balls, support functions, obstacle tests),
``workspace/`` (cell decompositions), ``system`` (``x+ = A x + B u + w``), ``zshape/`` (the
cross-sections ``Z``), ``zassignment`` (each pair's ``Z``) and ``problem`` (the pair problems).
It imports nothing above it (``tests/test_layers.py``).
"""
