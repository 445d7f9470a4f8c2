"""Learned tube cross-sections ``Z``.

The ``Z`` themselves are model data (:mod:`tubejax.model.zshape`): the parametrised families
(:mod:`tubejax.model.zshape.params`: 2-D polygons, n-D parallelotopes, the normalisation that
removes scale and translation, and the invariants), the ``learned_z.json`` file
(:mod:`tubejax.model.zshape.table`, with :func:`~tubejax.model.zshape.table.use_z_table` for
``make_z('learned', ...)`` and :func:`~tubejax.model.zshape.table.assignment_from_table`, the
cross-sections :func:`tubejax.abstraction.build_abstraction` runs with). Learning them is here:

* :mod:`.lagrangian` -- ``t*(Z)`` of the margin-form tube LP and its envelope-theorem gradient
  (the derivation is in its docstring);
* :mod:`.margin` -- :class:`PairMargins`: ``t*`` of a batch of LPs as a ``jax.custom_vjp``
  around the batched HiGHS solve (:mod:`.highs_duals`);
* :mod:`.learn` -- :func:`learn_z`: optax (Adam) on a smooth surrogate of the number of
  certified transitions, per cell shape (``learned``) or per pair (``learned_pair``);
* :mod:`.pairs` -- :func:`learn_pair_z` and Algorithm 2 with one ``Z`` per pair (the reference);
* :mod:`.build` -- a run's learned ``Z``: :func:`~.build.learn_table` (the ``learned_z.json`` of
  ``zshape=learned|learned_pair``);
* :mod:`.ccp` -- the comparison: configuration-constrained tubes (facet offsets as LP variables).

The names of the model's ``params`` and ``table`` that learning works with are re-exported here.
"""

from ...model.zshape.params import ZFamily, ZShapeError, family_for, polytope_from_z
from ...model.zshape.table import ZTable, ZTableError, active_z_table, file_sha256, load_z_table, use_z_table
from .learn import LearnedZ, LearnOptions, candidate_pairs, learn_z
from .margin import PairMargins
from .pairs import PairAbstraction, learn_pair_z, pair_abstraction, table_from_learned

__all__ = ["LearnOptions", "LearnedZ", "PairAbstraction", "PairMargins", "ZFamily", "ZShapeError", "ZTable",
           "ZTableError", "active_z_table", "candidate_pairs", "family_for", "file_sha256", "learn_pair_z",
           "learn_z", "load_z_table", "pair_abstraction", "polytope_from_z", "table_from_learned",
           "use_z_table"]
