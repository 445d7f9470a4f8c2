"""The transition system (Definition 2) with its evidence: the data, its files and its graph.

:mod:`~tubejax.transitions.transition_system` (the system), ``records`` (edges and non-edge
evidence), ``file_format`` and ``reading`` (its files, docs/reference/formats.md#transitionsjson),
``graph_export``, ``source_files`` and ``provenance``. Importing this package imports none of them.
"""
