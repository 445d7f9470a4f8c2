"""Every radius from one solve (docs/math/radius.md): the critical disturbance
``rho*(i, j, L)`` of every candidate instance, the step functions ``n_edges(rho)``, and the
verified transition system at any requested radius and any ``L_max`` up to the solved one.

* :mod:`.table` -- :func:`solve_radius_table` (one batched solve, candidates pruned at
  ``rho = 0``: sound for every ``rho >= 0``), :class:`RadiusTable` (per instance the value and
  its bracket; per pair the critical value, :meth:`RadiusTable.critical`, made exact by HiGHS
  with :meth:`RadiusTable.refine`; :meth:`RadiusTable.n_edges` the step function);
* :mod:`.step_functions` -- :class:`StepFunction`, ``n(rho)`` from values (:func:`step_function`);
* :mod:`.systems` -- :func:`transition_system_at`: the transition system at a radius, every
  edge confirmed by HiGHS with the tube for that radius stored and proved, every non-edge
  proved by a dual bound or HiGHS, each edge carrying its ``rho_star``;
* :mod:`.report` -- :func:`radius_document`, the ``radius.json`` of ``experiments/radius.py``,
  and the inputs record at a radius (:func:`record_at_radius`);
* the checks of ``rho_star`` that ``python -m tubejax verify`` runs are :mod:`tubejax.verify.rho`.
"""

from .report import RADIUS_FORMAT, RADIUS_VERSION, radius_directory, radius_document, record_at_radius
from .step_functions import RHO_STEP_TOL, StepFunction, step_function
from .systems import RHO_TIE_TOL, check_scaled_disturbance, n_edges_vs_L_max, transition_system_at
from .table import PairCritical, RadiusTable, RadiusTableOptions, highs_map, solve_radius_table

__all__ = ["RADIUS_FORMAT", "RADIUS_VERSION", "RHO_STEP_TOL", "RHO_TIE_TOL", "PairCritical", "RadiusTable",
           "RadiusTableOptions", "StepFunction", "check_scaled_disturbance", "highs_map", "n_edges_vs_L_max", "radius_directory",
           "radius_document", "record_at_radius", "solve_radius_table", "step_function", "transition_system_at"]
