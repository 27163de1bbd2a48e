"""Ray-level helper of the DDF: unit normals from gradients (its box entry: ddfbench.core.geometry.box_entry)."""

from __future__ import annotations

import numpy as np


def unit_normals(grad: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (N,3) from gradients (N,3), signed so n.d < 0 for unit directions (N,3), and valid (N,).

    Where the gradient vanishes or is not finite the normal falls back to -d, flagged invalid.
    """
    norm = np.linalg.norm(grad, axis=1)
    valid = np.isfinite(norm) & (norm > 1e-6)
    n = np.where(valid[:, None], grad / np.where(valid, norm, 1.0)[:, None], -directions)
    n[np.einsum("ij,ij->i", n, directions) > 0] *= -1
    return n.astype(np.float32), valid
