"""Point-of-view sampling (the DDF paper's baseline): every pixel of cameras around the shape.

Cameras sit on a sphere of `radius` about the origin, looking at it, at n_azimuth x n_polar
positions (azimuths 2 pi i / n_azimuth, polar angles (j + 1/2) pi / n_polar from +z; the paper's
10 x 5 = 50), each with resolution^2 pixel rays over a square field of view of fov_deg.
A pixel ray becomes a sample where it enters the field box (or at the camera if the camera is in
the box); rays that miss the box are dropped (`outside_box`). Rays: with s_p = 0 one sample per
pixel, label = the oracle's first hit from the sample; with s_p > 0, s_p samples per pixel placed
before the first hit (distances back from the hit by the `steps` rule, from t_min; along the box
chord for a miss), each re-cast by the oracle. SDF: max(1, s_p) points per pixel ray, stratified
along its whole chord through the box (and the shape), labelled by the oracle's signed distance.
Size: 50 resolution^2 max(1, s_p) labels, 29 bytes per ray label: resolution 128, s_p 10 is
8.2e6 labels, 0.24 GB.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import pinhole_rays, ray_box
from ddfbench.sampling import params
from ddfbench.sampling.collect import Collector, chunks
from ddfbench.sampling.samples import Samples
from ddfbench.sampling.steps import STEP_RULES, marching_distances
from ddfbench.truth.oracle import Oracle
from ddfbench.truth.shapes import Shape

KEYS = ("n_azimuth", "n_polar", "resolution", "radius", "fov_deg", "s_p", "steps", "t_min", "box", "max_samples")
CHUNK = 1 << 21


def read_config(cfg: Mapping[str, Any]) -> dict[str, Any]:
    """The validated parameters of a pov config (all keys of conf/sampling/pov.yaml)."""
    params.check_keys(cfg, KEYS)
    p = {k: params.count(cfg, k) for k in ("n_azimuth", "n_polar", "resolution", "max_samples")}
    p.update(radius=params.positive(cfg, "radius"), fov_deg=params.positive(cfg, "fov_deg"),
             s_p=params.count(cfg, "s_p", minimum=0), steps=params.choice(cfg, "steps", STEP_RULES),
             t_min=params.positive(cfg, "t_min"), box=params.positive(cfg, "box"))
    if p["fov_deg"] >= 180:
        raise InputError(f"sampling.fov_deg={p['fov_deg']}: must be below 180")
    return p


def camera_centers(n_azimuth: int, n_polar: int, radius: float) -> np.ndarray:
    """(n_azimuth * n_polar, 3) float64 camera positions on the sphere of `radius`."""
    azim = 2 * np.pi * np.arange(n_azimuth) / n_azimuth
    polar = (np.arange(n_polar) + 0.5) * np.pi / n_polar
    a, po = np.meshgrid(azim, polar, indexing="ij")
    s = np.sin(po)
    return radius * np.stack([s * np.cos(a), s * np.sin(a), np.cos(po)], axis=-1).reshape(-1, 3)


def pixel_rays(centers: np.ndarray, resolution: int, fov_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Origins and unit directions (C * resolution^2, 3) float64 of cameras looking at the origin, z up."""
    rays = [pinhole_rays(c, np.zeros(3), (0.0, 0.0, 1.0), fov_deg, resolution, resolution) for c in centers]
    return np.concatenate([o for o, _ in rays]), np.concatenate([d for _, d in rays])


def sample(shape: Shape, oracle: Oracle, cfg: Mapping[str, Any], kind: str,
           rng: np.random.Generator) -> tuple[Samples, dict[str, Any], dict[str, int]]:
    """Samples of `kind` ("rays" | "sdf") from camera rays, the parameters used, rejection counts."""
    p = read_config(cfg)
    centers = camera_centers(p["n_azimuth"], p["n_polar"], p["radius"])
    inside = oracle.occupancy(centers)
    if inside.any():
        c = centers[np.argmax(inside)].round(3).tolist()
        raise InputError(f"sampling.radius={p['radius']}: camera at {c} is inside shape {shape.name}; use a larger radius")
    origins, dirs = pixel_rays(centers, p["resolution"], p["fov_deg"])
    t_in, t_out = ray_box(origins, dirs, p["box"])
    start = np.maximum(t_in, 0.0)
    in_box = t_out > start
    rejected = {"outside_box": int((~in_box).sum())}
    x0 = origins[in_box] + start[in_box, None] * dirs[in_box]
    dirs, chord = dirs[in_box], (t_out - start)[in_box]
    per_ray = max(1, p["s_p"])
    out = Collector(p["max_samples"], f"pov sampling of {shape.name}")
    out.expect(len(x0) * per_ray, kind)
    for sl in chunks(len(x0), CHUNK // per_ray):
        x, d, length = x0[sl], dirs[sl], chord[sl]
        if kind == "sdf":
            along = (np.arange(per_ray) + rng.random((len(x), per_ray))) / per_ray * length[:, None]
            pts = (np.repeat(x, per_ray, axis=0) + along.reshape(-1, 1) * np.repeat(d, per_ray, axis=0)).astype(np.float32)
            out.add(pts, sdf=oracle.signed_distance(pts))
            continue
        t0 = oracle.hit_distance(x, d)
        if p["s_p"] == 0:
            out.add(x, d, t0)
            continue
        end = np.where(np.isfinite(t0), t0, length)
        back = marching_distances(p["steps"], p["s_p"], p["t_min"], end, rng)  # distance back from the hit
        ok = back <= end[:, None]  # a hit nearer than t_min leaves no room before it
        rejected["too_short"] = rejected.get("too_short", 0) + int((~ok).sum())
        r, k = np.nonzero(ok)
        pts = (x[r] + (end[r] - back[r, k])[:, None] * d[r]).astype(np.float32)
        out.add(pts, d[r], oracle.hit_distance(pts, d[r]))
    info = dict(p, n_cameras=int(len(centers)), pixel_rays=int(len(origins)))
    return out.samples(), info, rejected
