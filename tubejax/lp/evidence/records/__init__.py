"""The LPs, one :class:`~tubejax.lp.declarations.formulation.Formulation` per module.

Each module here defines ``FORMULATION``; :mod:`tubejax.lp.evidence.registry` imports every
module of this package, so a new LP is one new file (docs/howto/extending.md#a-new-lp).
"""
