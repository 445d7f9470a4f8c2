"""The model, the bottom layer: the sets, the system, the workspace and the problems made of them.

``geometry/``
    Convex polytopes (H/V), balls, support functions and obstacle tests.
``workspace/``
    Grid maps, polygon workspaces and box grids as a :class:`~tubejax.model.workspace.CellDecomposition`.
``system``
    The disturbed linear system ``x+ = A x + B u + w`` (:class:`~tubejax.model.system.LinearSystem`).
``zshape/``
    The cross-sections ``Z``: the fixed kinds by name (``kinds``), the parametrised families of a
    learned ``Z`` (``params``) and the ``learned_z.json`` table (``table``).
``zassignment``
    Which cross-section ``Z`` each ordered pair's tubes use.
``problem``
    :class:`~tubejax.model.problem.TubeProblem`, the data of one pair problem, and from a
    decomposition and a system the tube problems of pairs and a horizon.

The bottom layer: the LP layer and everything above import it, and it imports nothing above it
(``tests/test_layers.py``).
"""
