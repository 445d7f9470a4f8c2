"""One record per LP: everything a method needs from its formulation, in one place.

A :class:`Formulation` names an LP (``'tube'``, ``'openloop'``, ``'exact2d'``, which solves none) and
holds its pieces (below). Whatever depends on the LP -- proving, deciding exactly, confirming with
HiGHS, choosing a solver, the radius analysis, checking a stored file -- asks this record
(:func:`formulation`, :func:`formulation_of`). The records live one per file in
:mod:`tubejax.lp.evidence.records`, so adding an LP is one new file there
(docs/howto/extending.md#a-new-lp).
"""

from __future__ import annotations

from typing import Callable, NamedTuple

from .margin_operator import MarginOperator

__all__ = ["Formulation", "PdhgForm", "RadiusForm"]


class PdhgForm(NamedTuple):
    """An LP's form on the batched PDHG engine (:class:`~tubejax.lp.batch.batch_solver.PdhgBatchSolver`): the
    ``pdhg`` of its :class:`Formulation` (margin form) and of its :class:`RadiusForm` (radius
    form). Its :class:`~.margin_operator.MarginOperator` and module-level functions, and nothing that reads
    a verdict: the engine derives the setup, the flat operator and the host re-check of the certificates
    from ``operator`` (:mod:`tubejax.lp.engines.pdhg_adapters`: ``pdhg_setup``, ``flat_ops``,
    ``host_flat_certificates``) and takes the HiGHS verdict, the translates' confirmation and the radius
    optimum from the evidence layer, of the record that holds this very object
    (:func:`~tubejax.lp.evidence.registry.formulation_of_form`: by identity, so no form can be taken for
    another LP's).

    Attributes
    ----------
    operator : MarginOperator
        The LP's matrix-free operator ``K`` (its rows, bounds and scaling).
    group_key : callable
        ``group_key(problem) -> tuple``: the static shape without the horizon; equal keys and
        padded horizons share one compiled executable.
    facet_counts : callable
        ``facet_counts(problem) -> tuple of int``: facets of the sets the rows constrain, padded by
        the engine to the largest seen so far, so executables are reused.
    data : callable
        ``data(problems, L_pad, f_pad, share, W0) -> (shape, data)``: the group's static shape and host
        data (float64, unscaled, batch axis last; ``W0`` the unit disturbance of a radius form, else
        ``None``; ``share``: store coefficients every instance shares once, where the LP can).
    batched : callable
        ``batched(problem) -> bool``: False sends the problem to HiGHS whole (a row family the
        operator does not model).
    radius : callable or None
        The radius form's start ``radius(shape, problems) -> x_ref``, a primal pytree (batch axis last):
        it computes optima (``rho*``, the optimise mode), not verdicts; HiGHS gives the optimum of a
        problem that is not batched (:func:`~tubejax.lp.evidence.radius_lp.radius_highs_optimum`).
        ``None``: the margin form.
    point : callable, optional
        ``point(shape, z, problem)``: one instance's flat primal ``z`` (``(n,)``, ``t`` last) as the
        LP's evidence type; without it ``optimise`` returns ``z``.
    translates : bool
        Confirm a group of exact translates of one problem together
        (:func:`~tubejax.lp.evidence.translate_verdicts.highs_translate_verdicts`, the tube LP's);
        else each is confirmed on its own.
    dual_key : callable, optional
        ``dual_key(problem) -> hashable``: equal keys have the same rows up to right-hand sides, so
        the engine tries a refuting dual on them before they enter the pool
        (:func:`~tubejax.lp.batch.sign_mode.stream_group`).
    ruiz : bool
        The margin form's ``ruiz_iters='auto'`` reads the state dimension ``shape.n``
        (:func:`~tubejax.lp.engines.pdhg.ruiz_passes`); else its rows stay unscaled.

    ``translates`` and ``dual_key`` say what the LP has, not a switch: the library runs every LP with
    what its form declares. A benchmark or test that measures the engine without one builds its
    variant itself, replacing the field on its solver's form (``solver.form =
    solver.form._replace(dual_key=None)``: scripts/bench_reuse_duals.py, experiments/scaling.py
    ``--no-translation-proofs``).
    """

    operator: MarginOperator
    group_key: Callable
    facet_counts: Callable
    data: Callable
    batched: Callable
    radius: Callable | None = None
    point: Callable | None = None
    translates: bool = False
    dual_key: Callable | None = None
    ruiz: bool = False


class RadiusForm(NamedTuple):
    """An LP's radius-parametric form (module-level functions, so helper processes can run them).

    Attributes
    ----------
    rows : callable
        ``rows(problem, W0) -> (lp, c)``: the LP's dense margin-form rows at ``rho = 0`` (``W = {0}``)
        and ``c``, shape ``(n_rows,)``: ``rho``'s coefficient in each unit row (``>= 0``).
    reference : callable
        ``reference(problem) -> x_ref``, shape ``(n_x,)``: a point satisfying every row without
        ``rho`` strictly, in the LP's column layout (what bounds ``rho`` from below).
    pdhg : PdhgForm or None
        Its form on the batched engine in optimise mode.
    """

    rows: Callable
    reference: Callable
    pdhg: PdhgForm | None = None


class Formulation(NamedTuple):
    """The pieces of one LP (all module-level functions, so helper processes can run them).

    Attributes
    ----------
    name : str
        The method name a config chooses (``abstraction.method``) and transition files record.
    families : tuple of RowFamily
        Its row families, in row order; ``()`` for a method without an LP.
    rank : int
        Its place in lists and messages (lowest first).
    evidence_type, exact_type : type or None
        The evidence it stores, in floats (``Tube``, ``OpenLoopPlan``) and in rationals
        (``ExactTube``, ``ExactPlan``, with ``coerce`` and ``to_float``).
    lp_type : type or None
        What :attr:`build` returns (``TubeLP``, ``OpenLoopLP``).
    build : callable or None
        ``build(prob) -> lp``: the dense margin-form LP HiGHS solves.
    violation, exact_violation : callable or None
        ``(prob, evidence) -> float`` / ``Fraction``: the float64 and exact checks (``<= 0``
        exactly: a proof).
    terms : dict of str to callable
        ``terms[arithmetic](prob)``, ``arithmetic`` in ``('float', 'exact')``: the data its families read.
    rational_lp : callable or None
        ``rational_lp(prob, lp) -> RationalLP``: ``lp`` row for row in rationals.
    bounds : callable or None
        ``bounds(prob, lp) -> (lb, ub)``: rational bounds of ``lp``'s columns where its basis puts a
        vertex (lists of Fractions).
    implied_bounds : callable or None
        ``implied_bounds(prob, lp) -> (lb, ub)``: the bounds a certificate of infeasibility uses, exact
        and never tighter than the truth (:func:`~tubejax.lp.evidence.rows.implied_tube_bounds`:
        those Problem 2 implies; the open loop's, ``U``'s box).
    from_point : callable or None
        ``from_point(lp, x) -> exact evidence``: a rational point of ``lp`` (``lp.index.n_x``
        rationals) as rational evidence.
    evidence_names : tuple of str
        The evidence's array names in transition files (``('p', 'eps', 'u')``).
    provenance : str
        The provenance of its HiGHS verdict (:func:`~tubejax.lp.evidence.verdict.highs_verdict`).
    pdhg : PdhgForm or None
        Its form on the batched PDHG engine; ``None``: HiGHS only.
    radius : RadiusForm or None
        Its radius-parametric form (:class:`RadiusForm`, docs/math/radius.md;
        its rows in :mod:`~tubejax.lp.declarations.radius_rows`); ``None``: no radius analysis.
    tubes : bool
        Whether its evidence is a tube ``Q_l = p_l + eps_l Z`` per step (``Z`` shapes the LP,
        Algorithm 1 and the temporal-logic labels read it).
    translation_classes : bool
        Whether its LP is exactly invariant under the translations of
        :mod:`tubejax.abstraction.translation_classes`.
    dimensions : tuple of int
        The state dimensions it works in; ``()``: any.
    exact_reference : bool
        Whether its result is the most any feedback can achieve (``exact2d``): the reference for the
        other methods' conservatism.
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
    implied_bounds: Callable | None = None
    from_point: Callable | None = None
    evidence_names: tuple = ()
    provenance: str = "highs"
    pdhg: PdhgForm | None = None
    radius: RadiusForm | None = None
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

