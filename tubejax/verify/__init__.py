"""Prove a saved transition system from its sources: ``python -m tubejax verify DIR``
(:mod:`.verifier`; docs/howto/verify.md). Importing this package imports none of its modules;
``tj.verify`` stays :func:`tubejax.api.verify`.
"""
