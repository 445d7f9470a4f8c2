"""The transition system (Definition 2) with its evidence: the data, its files and its graph.

``transition_system``
    :class:`~tubejax.transitions.transition_system.TransitionSystem`: cells, edges, tubes,
    re-verification, ``save``/``load``, networkx.
``records``
    An edge and the evidence of the non-edges.
``file_format``
    The files ``<stem>.json`` and ``<stem>.npz`` (format version 4; 3 still loads): written and read strictly.
``reading``
    A validated transitions file -> a :class:`~tubejax.transitions.transition_system.TransitionSystem`.
``graph_export``
    The system as a graph: networkx, GraphML, GEXF, DOT.
``source_files``
    A system that saves, beside its files, the workspace text it was built from.
``provenance``
    Who wrote an output file: the tubejax version, the git commit and the command line.

Importing this package imports none of its modules (``import tubejax`` reads only ``provenance``).
"""
