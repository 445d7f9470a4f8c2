"""The batched solver: groups, streams, certifies and confirms (docs/explanation/implementation.md#the-lp-layer).

:class:`~.batch_solver.PdhgBatchSolver` with its sign and optimise modes (:mod:`.sign_mode`,
:mod:`.optimise_mode`), run on an LP record's ``pdhg`` (:func:`~.batch_solver.pdhg_solver`) with the
HiGHS verdicts of the evidence layer, or on its radius form (``pdhg_solver(method, radius=True)``). The top of the
LP layer: it may import declarations, engines and evidence.
"""
