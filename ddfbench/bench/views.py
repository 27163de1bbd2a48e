"""The rays the benchmarks cast: the one view they render (a pinhole camera looking at the origin,
render.camera.Camera) and incoherent rays through the field box."""

from __future__ import annotations

import numpy as np

from ddfbench.core.geometry import BOX_HALF
from ddfbench.render.camera import Camera
from ddfbench.sampling.box import uniform_in_box
from ddfbench.sampling.directions import uniform_directions

EYE = (0.9, 0.5, 1.2)  # camera position in the normalized frame: the shape fills most of a 40 degree view


def view_rays(size: int, eye=EYE, fov_deg: float = 40.0) -> tuple[np.ndarray, np.ndarray]:
    """size^2 pixel rays of a camera at `eye` looking at the origin (y up): origins, unit directions (size^2, 3) float32."""
    return Camera(np.asarray(eye, float), np.zeros(3), fov_deg, int(size), int(size)).rays()


def orbit_eye(ray_seed: int, eye=EYE) -> np.ndarray:
    """The camera position of ray seed k (the race's repeats): `eye` turned (k - 1) * 72 degrees about the
    vertical (y) axis, so seeds 1-5 view the shape from five directions around it and seed 1 is `eye` itself."""
    a = np.deg2rad(72.0 * (int(ray_seed) - 1))
    x, y, z = (float(v) for v in eye)
    return np.array([x * np.cos(a) + z * np.sin(a), y, -x * np.sin(a) + z * np.cos(a)])


def incoherent_rays(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n rays (n, 3), (n, 3) float32: origins uniform in the field box, unit directions uniform on the sphere."""
    rng = np.random.default_rng(seed)
    d = uniform_directions(rng, n)
    return uniform_in_box(rng, n, BOX_HALF), d
