"""The LP layer: every (pair, horizon) question is a margin-form LP (docs/math/margins.md).

Its folders are layers, each importing only the ones before it (``tests/test_layers.py`` checks):

``declarations/``
    What each LP is, nothing solved: the row families (``row_families``, ``tube_families``,
    ``openloop_families``), the dense builders for HiGHS (``tube_lp``, ``openloop_lp``), the matrix-free
    batched operators and their data (``tube_operator``, ``openloop_operator``, ``*_operator_data``), the
    radius form's disturbance, the :class:`~tubejax.lp.declarations.formulation.Formulation` record type and
    the record a formulation hands the batched engine (``pdhg_formulation``).
``engines/``
    Numerical solvers that know no verdict: the batched restarted-Halpern PDHG (``pdhg``) with its float64
    weak-duality certificates (``certify``, ``objective_bounds``), the fixed-width pool that streams
    instances through one compiled executable (``pool``), HiGHS (``highs``) and the workers and helper
    process running it (``workers``, ``helper_process``).
``evidence/``
    What makes a verdict trustworthy: the verdicts with their HiGHS confirmation (``verdict``,
    ``translate_verdicts``), exact (rational) checks, proofs and decisions (``prove``, ``decide``, ...).
``batch/``
    The batched solver that groups, streams, certifies and confirms (``batch_solver``, ``sign_mode``,
    ``optimise_mode``) and the per-LP adapters that plug a formulation into it (``tube_pdhg``,
    ``openloop_pdhg``, ``radius_pdhg``).
"""
