"""What is done with transition systems: control, specifications, radii, learned ``Z``, sweeps, figures.

``control/``
    Planning over the transition system, the tube controller and vectorised simulation.
``spec/``
    LTLf formulas (DFAs) and LTL formulas over infinite runs (Büchi automata, cheapest lassos), by Spot;
    the sound product, patrols and Spot-checked simulated runs.
``radius_analysis/``
    Every radius from one solve.
``zshape/``
    Learned tube cross-sections ``Z``.
``conservatism/``
    The reach-avoid limit in 2-D beside every method's winning set.
``sweep_results``
    Sweep results collected into one table, with the jobs that have none and the conservatism.
``plot/``
    Figures (``tj.plot``).
"""
