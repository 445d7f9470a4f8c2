"""The tube LP (Problem 2, SPEC section 2)."""
