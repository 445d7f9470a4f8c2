"""The LP layer: every (pair, horizon) question is a margin-form LP (docs/math/margins.md). Its folders
``declarations/``, ``engines/``, ``evidence/`` and ``batch/`` are layers, each importing only the ones
before it (docs/explanation/implementation.md#the-lp-layer; ``tests/test_layers.py`` checks).
"""
