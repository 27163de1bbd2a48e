"""Pinhole cameras: where they stand and the rays they shoot.

Pixel (row i, column j) of a width×height image looks through the image-plane point at
u = (j + 0.5 + jx)/width, v = (i + 0.5 + jy)/height, row 0 at the top; (jx, jy) ∈ [-0.5, 0.5) is a
per-sample jitter (zero for the pixel centre). fov_deg is the vertical field of view.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ddfbench.core.geometry import pinhole_rays, unit


@dataclass(frozen=True, eq=False)
class Camera:
    """position, look_at, up: (3,) float64 in the normalized frame; fov_deg vertical; width, height in pixels."""

    position: np.ndarray
    look_at: np.ndarray
    fov_deg: float
    width: int
    height: int
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))

    def rays(self, jitter: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Rays of every pixel, S samples each (geometry.pinhole_rays in float32).

        jitter: (S, height, width, 2) offsets in pixels from the centre, or None for one centred sample.
        Returns origins and unit directions, both (S·height·width, 3) float32, ordered sample, row, column.
        """
        o, d = pinhole_rays(self.position, self.look_at, self.up, self.fov_deg, self.width, self.height, jitter)
        return o.astype(np.float32), d.astype(np.float32)


def orbit_cameras(n: int, radius: float, elevation_deg: float, azimuth_deg: float, fov_deg: float,
                  width: int, height: int, look_at: np.ndarray = np.zeros(3),
                  up: np.ndarray = np.array([0.0, 1.0, 0.0])) -> tuple[Camera, ...]:
    """n cameras on a circle of `radius` around look_at, evenly spaced in azimuth from azimuth_deg,
    raised elevation_deg above the plane normal to `up` (azimuth 0 looks from +z when up is +y)."""
    up = unit(np.asarray(up, float))
    ref = np.array([0.0, 0.0, 1.0]) if abs(up[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e2 = unit(ref - (ref @ up) * up)
    e1 = np.cross(up, e2)
    el = math.radians(elevation_deg)
    cams = []
    for k in range(n):
        az = math.radians(azimuth_deg + 360.0 * k / n)
        offset = radius * (math.cos(el) * (math.sin(az) * e1 + math.cos(az) * e2) + math.sin(el) * up)
        cams.append(Camera(np.asarray(look_at, float) + offset, np.asarray(look_at, float), fov_deg, width, height, up))
    return tuple(cams)
