"""The LP layer: every (pair, horizon) question is a margin-form LP (docs/math/margins.md).

It grows by formulations, not by twins:

``formulations/``
    One record per LP in ``records/`` (a :class:`~tubejax.lp.declarations.formulation.Formulation`,
    found by ``registry``: what every method-dependent step asks), and one sub-package per LP (``tube``: Problem 2; ``openloop``: the open-loop
    baseline of docs/math/open-loop.md; ``radius``: both in the radius-parametric form of docs/math/radius.md, solved to
    optimality by the engine's optimise mode). Each provides the same few pieces: a dense builder (rows for HiGHS),
    a matrix-free batched operator (``K``, ``K^T`` from the geometry, batch axis last)
    and a float64 checker of the evidence it stores.
``solvers/``
    The engines that serve every formulation: the batched restarted-Halpern PDHG
    (``pdhg``), the fixed-width pool that streams instances through one compiled
    executable (``pool``), the batch solver that groups, certifies and confirms
    (``batched``), HiGHS (``highs``) and the helper process running it (``workers``).
``evidence/``
    What makes a verdict trustworthy: float64 weak-duality certificates
    (``certify``) and the verdicts with their HiGHS confirmation (``verdict``).
"""
