"""The radius-parametric form of the tube and open-loop LPs (SPEC section 4a)."""
