"""Render accuracy of a family against the oracle render from the same cameras, pooled over cameras.

- depth_mae: mean |t − t_ref| over pixels both renders hit (unit-cube units);
- normal_angle_deg: mean angle between the normals, same pixels;
- mask_iou: |A ∩ B| / |A ∪ B| of the hit masks (1 when both are empty);
- psnr_<image>: 10·log10(1 / MSE) of the radiance clipped to [0, 1], all pixels and channels;
  identical images get PSNR_CAP (a defined value, not inf, so records stay valid JSON).
When no pixel is hit by both, depth_mae and normal_angle_deg are None and depth_pixels_compared
is 0, so the empty overlap is explicit rather than a silent NaN.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ddfbench.render.integrator import Frames

PSNR_CAP = 100.0


def psnr(reference: np.ndarray, image: np.ndarray) -> float:
    """PSNR in dB of two linear images of equal shape (e.g. (C,H,W,3)), clipped to [0, 1]; PSNR_CAP when
    identical."""
    mse = float(np.mean((np.clip(reference, 0, 1) - np.clip(image, 0, 1)) ** 2))
    return PSNR_CAP if mse <= 10 ** (-PSNR_CAP / 10) else 10 * math.log10(1 / mse)


def normal_angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles in degrees between unit normals a and b (..., 3); atan2 form, exact near 0 and 180."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, axis=-1)))


def image_metrics(reference: Frames, frames: Frames, outputs: frozenset[str]) -> dict[str, Any]:
    """Metrics of `frames` against `reference` (same cameras; Frames: depth, mask (C,H,W), normal (C,H,W,3),
    images name -> (C,H,W,3)) -> dict: mask_iou, depth_pixels_compared, depth_mae, normal_angle_deg as
    `outputs` allow, and psnr_<image> per image of frames (module docstring)."""
    out: dict[str, Any] = {}
    both = reference.mask & frames.mask
    if "mask" in outputs:
        union = int(np.count_nonzero(reference.mask | frames.mask))
        out["mask_iou"] = 1.0 if union == 0 else int(np.count_nonzero(both)) / union
    if {"depth", "normal"} & outputs:
        out["depth_pixels_compared"] = int(np.count_nonzero(both))
    if "depth" in outputs:
        out["depth_mae"] = float(np.mean(np.abs(frames.depth[both] - reference.depth[both]))) if both.any() else None
    if "normal" in outputs:
        out["normal_angle_deg"] = (float(np.mean(normal_angles_deg(frames.normal[both], reference.normal[both])))
                                   if both.any() else None)
    for name, image in frames.images.items():
        out[f"psnr_{name}"] = psnr(reference.images[name], image)
    return out
