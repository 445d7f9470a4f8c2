"""Disturbance and input sets described by their support functions.

Only ``sigma_W(a) = max_{w in W} a.w`` enters the tube LP (docs/math/problem-data.md).
Each set also samples points (uniform inside, on the boundary) and returns the
maximiser of ``a.w`` (used by the adversarial simulation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .polytope import Polytope

__all__ = ["Ball", "support", "support_maximizer", "sample_uniform", "sample_boundary"]


@dataclass(frozen=True)
class Ball:
    """The 2-norm ball ``{w : ||w||_2 <= radius}`` in ``R^n``."""

    dim: int
    radius: float

    def __post_init__(self):
        if not np.isfinite(self.radius) or self.radius < 0:
            raise ValueError(f"ball radius must be a finite number >= 0, got {self.radius}")
        if self.dim < 1:
            raise ValueError(f"ball dimension must be >= 1, got {self.dim}")


SetLike = Ball | Polytope


def support(S: SetLike, a) -> np.ndarray:
    """Support function ``sigma_S(a)`` for directions of shape ``(..., n)``; returns shape ``(...)``.

    Ball: ``r ||a||_2``; polytope (box included): ``max_k a.v_k``.
    """
    a = np.asarray(a, float)
    if isinstance(S, Ball):
        return S.radius * np.linalg.norm(a, axis=-1)
    return S.support(a)


def support_maximizer(S: SetLike, a) -> np.ndarray:
    """A point ``w in S`` with ``a.w = sigma_S(a)``; ``a`` of shape ``(..., n)``."""
    a = np.asarray(a, float)
    if isinstance(S, Ball):
        # scale by the largest entry first: the norm of a tiny direction would underflow
        big = np.max(np.abs(a), axis=-1, keepdims=True)
        a = a / np.where(big > 0, big, 1.0)
        nrm = np.linalg.norm(a, axis=-1, keepdims=True)
        return S.radius * np.where(nrm > 0, a / np.where(nrm > 0, nrm, 1.0), 0.0)
    idx = np.argmax(a @ S.vertices.T, axis=-1)
    return S.vertices[idx]


def sample_uniform(S: SetLike, rng: np.random.Generator, size: int) -> np.ndarray:
    """``size`` points uniform in ``S``, shape ``(size, n)`` (rejection from the bounding box for polytopes)."""
    if isinstance(S, Ball):
        g = rng.standard_normal((size, S.dim))
        g /= np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
        rad = S.radius * rng.random(size) ** (1.0 / S.dim)
        return g * rad[:, None]
    lo, hi = S.bounding_box()
    out = np.empty((0, S.dim))
    while out.shape[0] < size:
        cand = lo + (hi - lo) * rng.random((2 * size + 16, S.dim))
        out = np.vstack([out, cand[S.contains(cand, tol=0.0)]])
    return out[:size]


def sample_boundary(S: SetLike, rng: np.random.Generator, size: int) -> np.ndarray:
    """``size`` points on the boundary of ``S``, shape ``(size, n)``.

    Ball: uniform on the sphere. Polytope: a uniform interior point pushed
    radially (from the vertex centroid) onto the boundary.
    """
    if isinstance(S, Ball):
        g = rng.standard_normal((size, S.dim))
        return S.radius * g / np.maximum(np.linalg.norm(g, axis=1, keepdims=True), 1e-300)
    c = S.centroid
    d = rng.standard_normal((size, S.dim))
    # largest s with H(c + s d) <= h
    Hd = d @ S.H.T
    slack = S.h - S.H @ c
    s = np.min(np.where(Hd > 1e-15, slack / np.where(Hd > 1e-15, Hd, 1.0), np.inf), axis=1)
    return c + s[:, None] * d
