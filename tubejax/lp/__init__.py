"""The LP layer: every (pair, horizon) question is a margin-form LP (docs/math/margins.md).

Its folders are layers, each importing only the ones before it (``tests/test_layers.py`` checks):
``declarations/`` (what each LP is; nothing solved), ``engines/`` (numerical solvers that know no
verdict, and each LP's form on the PDHG engine), ``evidence/`` (what makes a verdict trustworthy, and
each LP's record), ``batch/`` (the batched solver); docs/explanation/implementation.md#the-lp-layer
lists their modules.
"""
