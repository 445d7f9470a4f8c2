"""One record per LP: everything a method needs from its formulation, in one place.

A :class:`Formulation` names an LP (``'tube'``: Problem 2, ``'openloop'``: the open-loop
baseline, ``'exact2d'``: the exact polygon computation, which solves none) and holds its pieces:
the row families it declares, its evidence types, the dense builder (the HiGHS model), the float
and exact checkers, the terms builder per arithmetic, the rational LP and its exact variable
bounds, its batched PDHG adapter and its radius form, and what its evidence supports. Everything
that used to switch on the name of a method or the type of an LP or of its evidence -- proving,
deciding exactly, confirming with HiGHS, choosing a solver, the radius analysis, checking a stored
file -- asks this record instead (:func:`formulation`, :func:`formulation_of`).

The records live one per file in :mod:`tubejax.lp.evidence.records`; :mod:`tubejax.lp.evidence.registry` finds
them all, so adding an LP is one new file there (docs/howto/extending.md#a-new-lp).
"""

from __future__ import annotations

from typing import Callable, NamedTuple

__all__ = ["Formulation"]


class Formulation(NamedTuple):
    """The pieces of one LP (all module-level functions, so helper processes can run them).

    Attributes
    ----------
    name : str
        The method name a config chooses (``abstraction.method``) and transition files record.
    families : tuple of RowFamily
        Its row families, in row order (:mod:`tubejax.lp.declarations.row_families`); ``()`` for a
        method without an LP. Which state constraints it models is read from them.
    rank : int
        Its place in lists and messages (lowest first).
    evidence_type : type or None
        The float evidence it stores (``Tube``, ``OpenLoopPlan``): ``evidence_type(*arrays)``.
    exact_type : type or None
        The same in rationals (``ExactTube``, ``ExactPlan``), with ``coerce`` and ``to_float``.
    lp_type : type or None
        What :attr:`build` returns (``TubeLP``, ``OpenLoopLP``): an ``index`` with ``split`` /
        ``pack``, unit rows ``G``, ``g``, hard rows, bounds and ``t_max``.
    build : callable or None
        ``build(prob) -> lp``: the dense margin-form LP, the model HiGHS solves.
    violation : callable or None
        ``violation(prob, evidence) -> float``: the float64 check of its evidence (unit rows).
    exact_violation : callable or None
        ``exact_violation(prob, evidence) -> Fraction``: the exact check (``<= 0``: a proof).
    terms : dict of str to callable
        ``terms[arithmetic](prob)``, ``arithmetic`` in ``('float', 'exact')``: the data its families
        read (``TubeTerms``, ``PlanTerms``), in float64 or in rationals.
    rational_lp : callable or None
        ``rational_lp(prob, lp) -> RationalLP``: ``lp`` row for row in rationals.
    bounds : callable or None
        ``bounds(prob, lp) -> (lb, ub)``: exact rational bounds of ``lp``'s columns.
    implied_bounds : bool
        Whether an exact decision tightens ``rational_lp``'s bounds by the bounds Problem 2 implies
        (:func:`~tubejax.lp.evidence.decide.exact_tube_bounds`); the open-loop LP's only bounds
        are ``U``'s box, which is data.
    from_point : callable or None
        ``from_point(lp, x) -> exact evidence``: a rational point ``x`` of ``lp`` (a list of
        ``lp.index.n_x`` rationals, in its column layout) as rational evidence.
    evidence_names : tuple of str
        The names of the evidence's arrays, as transition files store them (``('p', 'eps', 'u')``).
    provenance : str
        The provenance of its HiGHS verdict (:func:`~tubejax.lp.evidence.verdict.highs_verdict`).
    pdhg : str or None
        Its adapter to the batched PDHG engine (a
        :class:`~tubejax.lp.declarations.pdhg_formulation.PdhgFormulation`), as ``'module:NAME'`` of
        :mod:`tubejax.lp.batch`, the layer above the records
        (:func:`tubejax.lp.batch.adapters.pdhg_adapter`); ``None``: HiGHS only.
    radius : RadiusForm or None
        Its radius-parametric form (:class:`~tubejax.lp.declarations.radius_rows.RadiusForm`,
        docs/math/radius.md); ``None``: no radius analysis.
    tubes : bool
        Whether its evidence is a tube ``Q_l = p_l + eps_l Z`` per step: its ``Z`` shapes the LP (a
        ``Z`` with more vertices than its cell applies), Algorithm 1 controls with it and the
        temporal-logic labels read it.
    translation_classes : bool
        Whether its LP is exactly invariant under the translations of
        :mod:`tubejax.abstraction.translation_classes` (one LP per class is solved).
    dimensions : tuple of int
        The state dimensions it works in; ``()``: any.
    exact_reference : bool
        Whether its result is the most any feedback can achieve (``exact2d``): the reference the
        conservatism of the other methods is measured against, drawn as such in the plots.
    product_path : bool
        Whether the product path (:mod:`tubejax.abstraction.product_store`) solves it.
    """

    name: str
    families: tuple
    rank: int
    evidence_type: type | None = None
    exact_type: type | None = None
    lp_type: type | None = None
    build: Callable | None = None
    violation: Callable | None = None
    exact_violation: Callable | None = None
    terms: dict | None = None
    rational_lp: Callable | None = None
    bounds: Callable | None = None
    implied_bounds: bool = False
    from_point: Callable | None = None
    evidence_names: tuple = ()
    provenance: str = "highs"
    pdhg: str | None = None
    radius: object = None
    tubes: bool = False
    translation_classes: bool = False
    dimensions: tuple = ()
    exact_reference: bool = False
    product_path: bool = False

    @property
    def solves_lp(self) -> bool:
        """Whether the method is an LP (``exact2d`` is not)."""
        return self.build is not None

    def exact(self, evidence):
        """``evidence`` (float or rational) as rational evidence, exactly."""
        return self.exact_type.coerce(evidence)

    def floats(self, evidence):
        """``evidence`` as float evidence (rational evidence rounded to float64, float as it is)."""
        return evidence.to_float() if type(evidence) is self.exact_type else evidence

    def is_exact(self, evidence) -> bool:
        """Whether ``evidence`` is rational evidence of this LP."""
        return type(evidence) is self.exact_type

