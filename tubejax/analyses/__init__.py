"""What is done with transition systems: ``control/`` (plans, the tube controller, simulation),
``spec/`` (LTLf and LTL specifications, by Spot), ``radius_analysis/``, ``zshape/`` (learned ``Z``),
``conservatism/`` (the reach-avoid limit), ``sweep_results`` and ``plot/`` (``tj.plot``).
"""
