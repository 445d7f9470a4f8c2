"""Engines: numerical LP solvers that know no verdict (docs/explanation/implementation.md#the-lp-layer).

The batched restarted-Halpern PDHG (:mod:`.pdhg`) with its float64 certificates (:mod:`.certify`,
:mod:`.objective_bounds`), the fixed-width pool (:mod:`.pool`), HiGHS (:mod:`.highs`) and the
workers and helper process that run it (:mod:`.workers`, :mod:`.helper_process`), and each LP's
form on the PDHG engine (:mod:`.tube_pdhg`, :mod:`.openloop_pdhg`, from :mod:`.pdhg_adapters`). Imports only :mod:`tubejax.lp.declarations` of the LP layer.
"""
