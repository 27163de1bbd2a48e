"""The axis-aligned field box [-h, h]^3: uniform points and ray-box intervals."""

from __future__ import annotations

import numpy as np


def uniform_in_box(rng: np.random.Generator, n: int, half: float) -> np.ndarray:
    """(n, 3) float32 points uniform in [-half, half]^3."""
    return rng.uniform(-half, half, (n, 3)).astype(np.float32)


def box_interval(origins: np.ndarray, directions: np.ndarray, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Ray parameters (N,), (N,) where rays (N,3),(N,3) enter and leave the box [lo, hi] (slab method).

    lo, hi: corners, scalars or (3,).

    The ray misses the box where enter > leave; both may be negative (box behind the origin).
    """
    o = np.asarray(origins, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / np.asarray(directions, np.float64)
        a, b = (lo - o) * inv, (hi - o) * inv
    enter, leave = np.fmin(a, b), np.fmax(a, b)  # fmin/fmax drop the NaN of a zero component on the slab's edge
    # a zero direction component: inside that slab the ray never leaves it (-inf, inf), outside never enters
    flat = np.asarray(directions) == 0
    inside = (o >= lo) & (o <= hi)
    enter = np.where(flat, np.where(inside, -np.inf, np.inf), enter)
    leave = np.where(flat, np.where(inside, np.inf, -np.inf), leave)
    return enter.max(axis=1), leave.min(axis=1)
