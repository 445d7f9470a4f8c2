"""The typed settings of one run of Algorithm 2 (:func:`~tubejax.abstraction.build.build_abstraction`).

:class:`AbstractionOptions` holds what decides the problem solved and how the run is split
(``memory_budget_mb``, ``shard``: never the result); :class:`RunIO` holds where a run reports
(its store, the per-step callback, the progress bar). The validated input model's
:class:`~tubejax.inputs.settings.AbstractionSettings` gives one by :meth:`AbstractionOptions.of_inputs`.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, NamedTuple

import numpy as np

from ..lp.evidence.registry import FORMULATIONS, lp_names

__all__ = ["AbstractionOptions", "RunIO"]


@dataclasses.dataclass(frozen=True)
class AbstractionOptions:
    """Algorithm 2's settings.

    Attributes
    ----------
    L_max : int
        Largest horizon tried, ``>= 1``.
    eps_min : float
        ``eps_l >= eps_min`` (C1).
    min_margin : float
        The robustness margin an edge must have, in ``[0, 1)`` (docs/math/margins.md); not for ``exact2d``.
    method : {'tube', 'openloop', 'exact2d'}
        The problem solved for each pair.
    zshape, z_scale : str, float
        Cross-section kind and size (``make_z``); with ``z`` given, ``zshape`` is only recorded.
    pruning : bool
        Apply the sound necessary conditions of :mod:`tubejax.abstraction.pruning` and the translation
        classes (:mod:`tubejax.abstraction.translation_classes`; the classes never change the result).
    memory_budget_mb : float or None
        Budget of the rounds' working set (``None``: one chunk per round); the result does not depend on it.
    shard : (int, int)
        ``(count, index)``: solve only the pairs whose source cell shard ``index`` of ``count`` owns.
    """

    L_max: int = 10
    eps_min: float = 0.0
    min_margin: float = 0.0
    method: str = "tube"
    zshape: str = "box"
    z_scale: float = 1.0
    pruning: bool = True
    memory_budget_mb: float | None = None
    shard: tuple[int, int] = (1, 0)

    def __post_init__(self):
        if not isinstance(self.L_max, (int, np.integer)) or self.L_max < 1:
            raise ValueError(f"L_max must be an integer >= 1, got {self.L_max!r}")
        m = self.min_margin
        if not (isinstance(m, (int, float, np.floating)) and 0.0 <= float(m) < 1.0):
            raise ValueError(f"min_margin must be a number in [0, 1), got {m!r}")
        record = FORMULATIONS.get(self.method)
        if float(m) > 0 and record is not None and not record.solves_lp:
            raise ValueError(f"min_margin applies to the methods that solve an LP ({', '.join(lp_names())}); "
                             f"{self.method} has no margin")

    def replace(self, **fields) -> "AbstractionOptions":
        """A copy with ``fields`` replaced (checked again)."""
        return dataclasses.replace(self, **fields)

    @classmethod
    def of_inputs(cls, inputs) -> "AbstractionOptions":
        """The options fixed by validated :class:`~tubejax.inputs.ProblemInputs` (its ``zshape``
        and ``abstraction`` sections: ``memory_budget_mb`` and ``shard`` included)."""
        a = inputs.abstraction
        return cls(L_max=a.L_max, eps_min=a.eps_min, min_margin=a.min_margin, method=a.method,
                   zshape=inputs.zshape.kind, z_scale=inputs.zshape.scale, pruning=a.pruning,
                   memory_budget_mb=a.memory_budget_mb, shard=(a.shard.count, a.shard.index))


class RunIO(NamedTuple):
    """Where a run reports: its store (:class:`~tubejax.abstraction.runstore.RunStore`), the
    callback after each step (``on_round(L, new_edges, new_tubes)``), the progress bar and the
    run's start (``time.perf_counter()``)."""

    store: Any = None
    on_round: Callable | None = None
    bar: Any = None
    t0: float = 0.0
