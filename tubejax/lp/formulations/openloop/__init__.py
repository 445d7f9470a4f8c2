"""The open-loop baseline LP (docs/math/open-loop.md)."""
