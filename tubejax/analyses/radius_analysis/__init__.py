"""Every radius from one solve (docs/math/radius.md): the critical disturbance ``rho*(i, j, L)`` of every
candidate instance, the step functions ``n_edges(rho)``, and the verified transition system at any
requested radius and any ``L_max`` up to the solved one.

:mod:`.radius_table` (:func:`solve_radius_table`, :class:`RadiusTable`), :mod:`.step_functions`,
:mod:`.systems` (:func:`transition_system_at`: every edge confirmed by HiGHS and proved, every
non-edge proved by a dual bound or HiGHS) and :mod:`.report` (``radius.json``); the checks of
``rho_star`` that ``python -m tubejax verify`` runs are :mod:`tubejax.verify.rho`.
"""

from .report import RADIUS_FORMAT, RADIUS_VERSION, radius_directory, radius_document, record_at_radius
from .step_functions import RHO_STEP_TOL, StepFunction, step_function
from .systems import RHO_TIE_TOL, check_scaled_disturbance, n_edges_vs_L_max, transition_system_at
from .radius_table import PairCritical, RadiusTable, RadiusTableOptions, highs_map, solve_radius_table

__all__ = ["RADIUS_FORMAT", "RADIUS_VERSION", "RHO_STEP_TOL", "RHO_TIE_TOL", "PairCritical", "RadiusTable",
           "RadiusTableOptions", "StepFunction", "check_scaled_disturbance", "highs_map", "n_edges_vs_L_max", "radius_directory",
           "radius_document", "record_at_radius", "solve_radius_table", "step_function", "transition_system_at"]
