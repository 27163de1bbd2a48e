"""Uniform points in the axis-aligned field box [-h, h]^3 (its ray intervals: ddfbench.core.geometry.ray_box)."""

from __future__ import annotations

import numpy as np


def uniform_in_box(rng: np.random.Generator, n: int, half: float) -> np.ndarray:
    """(n, 3) float32 points uniform in [-half, half]^3."""
    return rng.uniform(-half, half, (n, 3)).astype(np.float32)

