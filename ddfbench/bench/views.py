"""The one view the ray benchmarks render: a pinhole camera looking at the origin (render.camera.Camera)."""

from __future__ import annotations

import numpy as np

from ddfbench.render.camera import Camera

EYE = (0.9, 0.5, 1.2)  # camera position in the normalized frame: the shape fills most of a 40 degree view


def view_rays(size: int, eye=EYE, fov_deg: float = 40.0) -> tuple[np.ndarray, np.ndarray]:
    """size^2 pixel rays of a camera at `eye` looking at the origin (y up): origins, unit directions (size^2, 3) float32."""
    return Camera(np.asarray(eye, float), np.zeros(3), fov_deg, int(size), int(size)).rays()
