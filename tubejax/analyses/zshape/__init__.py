"""Learned tube cross-sections ``Z`` (issue 13).

* :mod:`.params` -- parametrised families of ``Z`` (2-D polygons, n-D parallelotopes), the
  normalisation that removes scale and translation, and the invariants (0 interior, vertex
  count, pairing by canonical order);
* :mod:`.lagrangian` -- ``t*(Z)`` of the margin-form tube LP and its envelope-theorem gradient
  (the derivation is in its docstring);
* :mod:`.margin` -- :class:`PairMargins`: ``t*`` of a batch of LPs as a ``jax.custom_vjp``
  around the batched HiGHS solve (:mod:`.highs_duals`);
* :mod:`.learn` -- :func:`learn_z`: optax (Adam) on a smooth surrogate of the number of
  certified transitions, per cell shape (``learned``) or per pair (``learned_pair``);
* :mod:`.table` -- the ``learned_z.json`` file and :func:`use_z_table` (``make_z('learned', ...)``);
* :mod:`.pairs` -- :func:`learn_pair_z` and Algorithm 2 with one ``Z`` per pair (the reference);
* :mod:`.build` -- a run's learned ``Z``: :func:`~.build.learn_table` (the ``learned_z.json`` of
  ``zshape=learned|learned_pair``) and :func:`~.build.assignment_from_table` (the cross-sections
  :func:`tubejax.abstraction.build_abstraction` runs with, a
  :class:`~tubejax.model.zassignment.ZAssignment` for per-pair ``Z``);
* :mod:`.ccp` -- the comparison: configuration-constrained tubes (facet offsets as LP variables).
"""

from .learn import LearnedZ, LearnOptions, candidate_pairs, learn_z
from .margin import PairMargins
from .pairs import PairAbstraction, learn_pair_z, pair_abstraction, table_from_learned
from .params import ZFamily, ZShapeError, family_for, polytope_from_z
from .table import ZTable, ZTableError, active_z_table, file_sha256, load_z_table, use_z_table

__all__ = ["LearnOptions", "LearnedZ", "PairAbstraction", "PairMargins", "ZFamily", "ZShapeError", "ZTable",
           "ZTableError", "active_z_table", "candidate_pairs", "family_for", "file_sha256", "learn_pair_z",
           "learn_z", "load_z_table", "pair_abstraction", "polytope_from_z", "table_from_learned",
           "use_z_table"]
