"""Geometry shared by every part: the field box, grid nodes, ray-box intervals, pinhole camera rays, Fourier
features.

Near the bottom of the import graph (numpy, torch and ddfbench.core.errors only). Frames: the normalized frame of the GT mesh
(unit cube [-0.5, 0.5]^3) inside the field box [-BOX_HALF, BOX_HALF]^3 (conf/config.yaml `domain`).
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import nn

from ddfbench.core.errors import InputError

BOX_HALF = 0.6  # half-side of the field box: the unit cube padded by 0.1 on every side


def grid_axis(resolution: int, domain: float) -> np.ndarray:
    """Node coordinates (resolution,) float32 along one axis of [-domain, domain]."""
    if int(resolution) < 2:
        raise InputError(f"mesh resolution {resolution}: must be at least 2")
    return np.linspace(-domain, domain, int(resolution), dtype=np.float32)


def grid_points(resolution: int, domain: float) -> np.ndarray:
    """All grid nodes (resolution^3, 3) float32 in C order (x slowest, z fastest)."""
    a = grid_axis(resolution, domain)
    return np.stack(np.meshgrid(a, a, a, indexing="ij"), axis=-1).reshape(-1, 3)


def ray_box(origins, directions, half: float = BOX_HALF):
    """Slab test: ray parameters (enter, leave), each (N,), where rays origins (N,3) + t directions (N,3)
    are inside the closed box [-half, half]^3; the ray misses the box where enter > leave.

    numpy arrays or torch tensors in, the same kind and dtype out; both t may be negative (box behind the
    origin), and nothing is clamped to t >= 0. The box is closed: a ray with a zero direction component lies
    in that slab for every t when its origin is inside or on the slab's faces and for no t otherwise, so
    a ray lying in a face of the box meets it along the face (an interval, never NaN).
    """
    xp = torch if isinstance(origins, torch.Tensor) else np
    flat = directions == 0
    inv = 1.0 / xp.where(flat, 1.0, directions)
    t0, t1 = (-half - origins) * inv, (half - origins) * inv
    always = flat & (xp.abs(origins) <= half)  # every t lies in this slab; flat & ~always: no t does
    enter = xp.where(always, -math.inf, xp.where(flat, math.inf, xp.minimum(t0, t1)))
    leave = xp.where(always, math.inf, xp.where(flat, -math.inf, xp.maximum(t0, t1)))
    return xp.amax(enter, 1), xp.amin(leave, 1)


def box_entry(origins, directions, half: float = BOX_HALF):
    """ray_box from t = 0 on, for rays origins (N,3) + t directions (N,3) against [-half, half]^3.

    Returns t_entry (N,) = max(enter, 0) (0 for an origin inside the box), t_exit (N,) = leave, and
    meets (N,) bool = t_exit >= t_entry (False where the ray misses the box or has it behind its origin).
    numpy arrays or torch tensors in, the same kind and dtype out.
    """
    enter, leave = ray_box(origins, directions, half)
    t_entry = enter.clip(min=0.0)
    return t_entry, leave, leave >= t_entry


def camera_basis(position, look_at, up) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit forward, right and up vectors (3,) float64 of a camera at position looking at look_at
    (right-handed: right = forward x up). Looking along `up`, any perpendicular up will do."""
    forward = unit(np.asarray(look_at, float) - np.asarray(position, float))
    up = np.asarray(up, float)
    if abs(float(forward @ unit(up))) > 0.999:
        up = np.array([1.0, 0.0, 0.0]) if abs(forward[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    right = unit(np.cross(forward, up))
    return forward, right, np.cross(right, forward)


def pinhole_rays(position, look_at, up, fov_deg: float, width: int, height: int,
                 jitter: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Rays of every pixel of a pinhole camera, S samples each, float64.

    Pixel (row i, column j), row 0 at the top, looks through the image-plane point at
    u = (j + 0.5 + jx)/width, v = (i + 0.5 + jy)/height; fov_deg is the vertical field of view.
    jitter: (S, height, width, 2) offsets (jx, jy) in pixels from the centre, or None for one centred sample.
    Returns origins and unit directions, both (S*height*width, 3), ordered sample, row, column.
    """
    if jitter is None:
        jitter = np.zeros((1, height, width, 2))
    forward, right, cam_up = camera_basis(position, look_at, up)
    half_h = math.tan(math.radians(fov_deg) / 2)
    half_w = half_h * width / height
    cols = (np.arange(width) + 0.5)[None, None, :] + jitter[..., 0]
    rows = (np.arange(height) + 0.5)[None, :, None] + jitter[..., 1]
    x = (2 * cols / width - 1) * half_w
    y = (1 - 2 * rows / height) * half_h
    d = forward + x[..., None] * right + y[..., None] * cam_up
    d = (d / np.linalg.norm(d, axis=-1, keepdims=True)).reshape(-1, 3)
    return np.broadcast_to(np.asarray(position, float), d.shape).copy(), d


def unit(v: np.ndarray) -> np.ndarray:
    """v (3,) scaled to unit length."""
    return v / np.linalg.norm(v)


class FourierFeatures(nn.Module):
    """Positional encoding v (..., c) -> [v, sin(s 2^k v), cos(s 2^k v) for k < n_freqs] (..., c (1 + 2 n_freqs)),
    the sines of every channel and frequency first (channel-major), then the cosines; s = `scale`."""

    def __init__(self, n_freqs: int, scale: float):
        super().__init__()
        self.register_buffer("freqs", scale * 2.0 ** torch.arange(int(n_freqs), dtype=torch.float32), persistent=False)

    def out_dim(self, c: int) -> int:
        return c * (1 + 2 * len(self.freqs))

    def forward(self, v: torch.Tensor) -> torch.Tensor:
        if len(self.freqs) == 0:
            return v
        a = (v[..., None] * self.freqs).flatten(-2)
        return torch.cat([v, torch.sin(a), torch.cos(a)], -1)
