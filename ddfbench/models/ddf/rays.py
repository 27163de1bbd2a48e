"""Ray-level helpers of the DDF: where a ray enters the field box, unit normals from gradients."""

from __future__ import annotations

import numpy as np

from ddfbench.geometry import ray_box


def box_entry(origins: np.ndarray, directions: np.ndarray, half: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """geometry.ray_box against [-half, half]^3 for rays (N,3),(N,3), from t = 0 on.

    Returns t_entry (N,) (0 for origins inside), t_exit (N,), both float32, and meets (N,) bool.
    """
    enter, leave = ray_box(origins, directions, half)
    t_entry = np.maximum(enter, 0.0)
    return t_entry.astype(np.float32), leave.astype(np.float32), leave >= t_entry


def unit_normals(grad: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (N,3) from gradients (N,3), signed so n.d < 0 for unit directions (N,3), and valid (N,).

    Where the gradient vanishes or is not finite the normal falls back to -d, flagged invalid.
    """
    norm = np.linalg.norm(grad, axis=1)
    valid = np.isfinite(norm) & (norm > 1e-6)
    n = np.where(valid[:, None], grad / np.where(valid, norm, 1.0)[:, None], -directions)
    n[np.einsum("ij,ij->i", n, directions) > 0] *= -1
    return n.astype(np.float32), valid
