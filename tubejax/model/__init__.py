"""The model, the bottom layer: the sets, the system, the workspace and the problems made of them.

``geometry/``
    Convex polytopes (H/V), balls, support functions and obstacle tests.
``workspace/``
    Grid maps, polygon workspaces and box grids as a :class:`~tubejax.model.workspace.CellDecomposition`.
``system``
    The disturbed linear system ``x+ = A x + B u + w`` (:class:`~tubejax.model.system.LinearSystem`).
``zassignment``
    Which cross-section ``Z`` each ordered pair's tubes use.
``problem``
    From a decomposition and a system to the tube problems of pairs and a horizon (the LP layer's
    :class:`~tubejax.lp.formulations.tube.dense.TubeProblem`).
``exact2d``
    Exact 2-D robust backward reachability: an upper bound on every method's edges.

The bottom layer: the LP layer and everything above import it (``tests/test_layers.py``). ``problem``
and ``exact2d`` state the model's questions with the LP layer's types, the two imports from here
that go up.
"""
