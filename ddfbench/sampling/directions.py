"""Unit directions: uniform on the sphere, the DDF paper's Eq. 10 (uniform angles), perpendiculars."""

from __future__ import annotations

import numpy as np


def uniform_directions(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3) float32 unit vectors, uniform on the sphere (normalized Gaussians)."""
    d = rng.standard_normal((n, 3), dtype=np.float32)
    norm = np.linalg.norm(d, axis=1, keepdims=True)
    while (bad := norm[:, 0] < 1e-6).any():  # practically never; keeps the division safe
        d[bad] = rng.standard_normal((int(bad.sum()), 3), dtype=np.float32)
        norm = np.linalg.norm(d, axis=1, keepdims=True)
    return d / norm


def paper_eq10_directions(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3) float32 unit vectors from uniform angles (DDF paper Eq. 10, literal).

    polar ~ U[0, pi] about +z and azimuth ~ U[0, 2 pi]: directions crowd at the poles
    (density proportional to 1 / sin(polar)). Kept only to reproduce the paper.
    """
    polar = rng.uniform(0.0, np.pi, n)
    azim = rng.uniform(0.0, 2.0 * np.pi, n)
    s = np.sin(polar)
    return np.stack([s * np.cos(azim), s * np.sin(azim), np.cos(polar)], axis=1).astype(np.float32)


DIRECTION_RULES = {"uniform": uniform_directions, "paper_eq10": paper_eq10_directions}


def random_perpendicular(rng: np.random.Generator, d: np.ndarray) -> np.ndarray:
    """(N, 3) float32 unit vectors perpendicular to the unit rows of d, at a uniform angle about each."""
    u = uniform_directions(rng, len(d))
    u -= np.einsum("ij,ij->i", u, d)[:, None] * d
    norm = np.linalg.norm(u, axis=1, keepdims=True)
    while (bad := norm[:, 0] < 1e-4).any():  # u was (almost) parallel to d: draw again
        v = uniform_directions(rng, int(bad.sum()))
        u[bad] = v - np.einsum("ij,ij->i", v, d[bad])[:, None] * d[bad]
        norm = np.linalg.norm(u, axis=1, keepdims=True)
    return (u / norm).astype(np.float32)
