"""Learning tube cross-sections ``Z`` (docs/howto/learned-z.md; the ``Z`` themselves and
``learned_z.json`` are model data, :mod:`tubejax.model.zshape`, re-exported here): the margin and its
gradient (:mod:`.lagrangian`, :mod:`.margin`), the learning (:mod:`.learn`, :mod:`.step`), per-pair
``Z`` (:mod:`.pairs`), a run's table (:mod:`.learn_run`) and the CCP comparison (:mod:`.ccp`).
"""

from ...model.zshape.params import ZFamily, ZShapeError, family_for, polytope_from_z
from ...model.zshape.z_table import ZTable, ZTableError, active_z_table, file_sha256, load_z_table, use_z_table
from .learn import LearnedZ, LearnOptions, candidate_pairs, learn_z
from .margin import PairMargins
from .pairs import PairAbstraction, learn_pair_z, pair_abstraction, table_from_learned

__all__ = ["LearnOptions", "LearnedZ", "PairAbstraction", "PairMargins", "ZFamily", "ZShapeError", "ZTable",
           "ZTableError", "active_z_table", "candidate_pairs", "family_for", "file_sha256", "learn_pair_z",
           "learn_z", "load_z_table", "pair_abstraction", "polytope_from_z", "table_from_learned",
           "use_z_table"]
