"""The tube LP (Problem 2, docs/math/tube-lp.md)."""
