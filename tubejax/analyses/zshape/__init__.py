"""Learning tube cross-sections ``Z`` (the ``Z`` themselves, their families and ``learned_z.json`` are
model data: :mod:`tubejax.model.zshape`; the names learning works with are re-exported here).

:mod:`.lagrangian` (``t*(Z)`` and its envelope-theorem gradient), :mod:`.margin` (:class:`PairMargins`,
a ``jax.custom_vjp`` around the batched HiGHS solve of :mod:`.highs_duals`), :mod:`.learn`
(:func:`learn_z`: Adam on a smooth surrogate of the certified transitions; its jitted step and loop in
:mod:`.step`), :mod:`.pairs` (one ``Z``
per pair, and Algorithm 2 with them: the reference), :mod:`.build` (a run's ``learned_z.json``) and
:mod:`.ccp` (the comparison: configuration-constrained tubes).
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
