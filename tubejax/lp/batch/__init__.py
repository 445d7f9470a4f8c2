"""The batched solver: groups, streams, certifies and confirms (docs/explanation/implementation.md#the-lp-layer).

:class:`~.batch_solver.PdhgBatchSolver` with its sign and optimise modes (:mod:`.sign_mode`,
:mod:`.optimise_mode`), the per-LP adapters that plug a formulation into it (:mod:`.tube_pdhg`,
:mod:`.openloop_pdhg`: margin and radius form, built from :mod:`.adapters`) and the radius form's solver
(:mod:`.radius_pdhg`). The top of the LP layer: it may import declarations, engines and evidence.
"""
