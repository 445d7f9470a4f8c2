"""The open-loop baseline LP (SPEC section 3)."""
