"""One render of a scene: primary rays, direct light with shadow rays, and diffuse path tracing.

Every ray goes through `CountedTracer.cast`, so any family renders through this same code and a
field's errors on secondary rays (shadow, bounce) show up in the image.

Sampling: sample 0 of every pixel goes through the pixel centre and gives the depth, mask and
normal images; samples 1..spp-1 are jittered uniformly in the pixel, and shaded / path images
average all spp samples (a scene without them casts sample 0 alone: nothing else would read the
others). Random numbers come from streams seeded by (seed, purpose) and are drawn per primary ray,
whatever the geometry, so two families rendered with the same seed use the same samples: their image
difference is geometry, not noise; and the depth image does not depend on what else a scene asks for.

Secondary rays (ε·scale rule): they start at p + ε·n, n the hit normal facing the incoming ray, ε =
scene.ray_offset in units of the unit cube (default 1e-3, 0.1 % of the shape's side) — far above
float32 precision there (~6e-8), and above the hit tolerance of sphere tracers, so no family sees its
own surface at t ≈ 0. A point light is occluded by a hit closer than the light.

Path tracing (diffuse, radiance in linear units): a path has at most max_depth vertices. At every
vertex next-event estimation adds albedo/π · E · cos θ for each light it sees (E = irradiance of a
directional light, intensity / r² of a point light); the next direction is cosine-weighted around n,
so the throughput is multiplied by the albedo exactly (BRDF·cos/pdf). Camera rays that miss see
`background`; bounce rays that escape see `environment`. Lights are delta lights, reached by
next-event estimation only, so nothing is counted twice. No Russian roulette: counts stay exact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ddfbench.core.representation import Representation
from ddfbench.render.counting import CountedTracer
from ddfbench.render.scene import Passes, Scene

_JITTER_STREAM, _BOUNCE_STREAM = 0, 1


@dataclass
class Frames:
    """One render of every camera (C cameras, H×W pixels).

    depth:  (C,H,W) float32 distance along the pixel-centre ray; inf on background.
    mask:   (C,H,W) bool, the pixel-centre ray hit.
    normal: (C,H,W,3) float32 unit normals facing the camera; zeros on background or when not needed.
    images: name ("shaded", "path") -> (C,H,W,3) float32 linear radiance, the mean of spp samples.
    shadow: (C,H,W) float32 share of the lights blocked at the primary hits (0 on background), or None.
    """

    depth: np.ndarray
    mask: np.ndarray
    normal: np.ndarray
    images: dict[str, np.ndarray] = field(default_factory=dict)
    shadow: np.ndarray | None = None


def primary_rays(scene: Scene, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Camera rays (C·spp·H·W, 3) origins and unit directions, ordered camera, sample, row, column."""
    rng = np.random.default_rng([seed, _JITTER_STREAM])
    c, s, h, w = len(scene.cameras), scene.spp, scene.height, scene.width
    jitter = rng.random((c, s, h, w, 2)) - 0.5
    jitter[:, 0] = 0.0
    rays = [cam.rays(jitter[i]) for i, cam in enumerate(scene.cameras)]
    return np.concatenate([r[0] for r in rays]), np.concatenate([r[1] for r in rays])


def cosine_directions(normals: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Cosine-weighted unit directions (M,3) around unit normals (M,3) from uniform numbers u (M,2)."""
    # orthonormal basis from one vector (Duff et al. 2017, branch-free)
    nx, ny, nz = normals[:, 0], normals[:, 1], normals[:, 2]
    sign = np.where(nz >= 0, 1.0, -1.0)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    t1 = np.stack([1 + sign * nx * nx * a, sign * b, -sign * nx], axis=1)
    t2 = np.stack([b, sign + ny * ny * a, -ny], axis=1)
    r, phi = np.sqrt(u[:, 0]), 2 * math.pi * u[:, 1]
    z = np.sqrt(np.maximum(0.0, 1.0 - u[:, 0]))
    d = (r * np.cos(phi))[:, None] * t1 + (r * np.sin(phi))[:, None] * t2 + z[:, None] * normals
    return (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)


def direct_light(tracer: CountedTracer, points: np.ndarray, normals: np.ndarray, scene: Scene,
                 shadows: bool) -> tuple[np.ndarray, np.ndarray]:
    """Reflected direct light at surface points (M,3) with unit normals (M,3).

    Returns radiance (M,3) float64 and the share of lights blocked by a shadow ray (M,) float64.
    Shadow rays are cast only toward lights in front of the surface (cos θ > 0).
    """
    m = len(points)
    radiance, blocked = np.zeros((m, 3)), np.zeros(m)
    brdf = np.asarray(scene.albedo) / math.pi
    for light in scene.lights:
        if light.kind == "directional":
            wi = np.broadcast_to(-np.asarray(light.vector), (m, 3))
            dist = np.full(m, np.inf)
            irradiance = np.broadcast_to(np.asarray(light.color), (m, 3))
        else:
            delta = np.asarray(light.vector) - points
            dist = np.maximum(np.linalg.norm(delta, axis=1), 1e-12)
            wi = delta / dist[:, None]
            irradiance = np.asarray(light.color)[None, :] / (dist * dist)[:, None]
        cos = np.einsum("ij,ij->i", normals, wi)
        lit = np.flatnonzero(cos > 0)
        if shadows and len(lit):
            origins = points[lit] + scene.ray_offset * normals[lit]
            hits = tracer.cast("shadow", origins, wi[lit], normals=False)
            to_light = np.linalg.norm(np.asarray(light.vector) - origins, axis=1) if light.kind == "point" else np.inf
            occluded = hits.t < to_light
            blocked[lit[occluded]] += 1
            lit = lit[~occluded]
        radiance[lit] += brdf * irradiance[lit] * cos[lit, None]
    return radiance, blocked / max(1, len(scene.lights))


def _bounces(tracer: CountedTracer, scene: Scene, passes: Passes, radiance: np.ndarray, active: np.ndarray,
             points: np.ndarray, normals: np.ndarray, seed: int) -> None:
    """Add the light of vertices 2..max_depth to `radiance` (N,3) of the N primary rays, in place.

    active: (M,) indices of primary rays whose path is alive at points (M,3) with normals (M,3).
    """
    rng = np.random.default_rng([seed, _BOUNCE_STREAM])
    albedo = np.asarray(scene.albedo)
    throughput = np.ones((len(active), 3))
    for _ in range(2, scene.max_depth + 1):
        u = rng.random((len(radiance), 2))[active]
        throughput *= albedo
        directions = cosine_directions(normals, u)
        origins = points + scene.ray_offset * normals
        hits = tracer.cast("bounce", origins, directions, normals=True)
        escaped = ~hits.hit
        radiance[active[escaped]] += throughput[escaped] * np.asarray(scene.environment)
        keep = hits.hit
        active, throughput = active[keep], throughput[keep]
        points = origins[keep] + hits.t[keep, None] * directions[keep]
        normals = hits.normal[keep]
        direct, _ = direct_light(tracer, points, normals, scene, passes.shadow_rays)
        radiance[active] += throughput * direct
        if not len(active):
            break


def render(rep: Representation, scene: Scene, passes: Passes, seed: int) -> tuple[Frames, dict[str, int]]:
    """Render every camera of `scene` with the passes given -> (Frames (C,H,W) images, see Frames; counts:
    `<kind>_rays` for primary / shadow / bounce, field_evals, backward_passes, trace_steps, intersect_calls,
    undecided_rays and any numeric stat a family adds)."""
    tracer = CountedTracer(rep, scene.chunk)
    c, s, h, w = len(scene.cameras), scene.spp, scene.height, scene.width
    origins, directions = primary_rays(scene, seed)
    if not (passes.shaded or passes.path):  # depth, mask and normal read sample 0 alone: cast no other sample
        origins, directions = (a.reshape(c, s, h * w, 3)[:, 0].reshape(-1, 3) for a in (origins, directions))
        s = 1
    hits = tracer.cast("primary", origins, directions, normals=passes.normals)
    centre = (slice(None), 0)
    normal = hits.normal if passes.normals else np.zeros((len(hits.t), 3), np.float32)  # zeros on misses
    frames = Frames(
        depth=hits.t.reshape(c, s, h, w)[centre].copy(),
        mask=hits.hit.reshape(c, s, h, w)[centre].copy(),
        normal=normal.reshape(c, s, h, w, 3)[centre].copy(),
    )
    if not (passes.shaded or passes.path):
        return frames, tracer.counts

    hit = np.flatnonzero(hits.hit)
    points = origins[hit] + hits.t[hit, None] * directions[hit]
    direct, blocked = direct_light(tracer, points, hits.normal[hit], scene, passes.shadow_rays)
    radiance = np.broadcast_to(np.asarray(scene.background), (len(hits.t), 3)).copy()
    radiance[hit] = direct
    if "shadow" in scene.outputs:
        share = np.zeros(len(hits.t))
        share[hit] = blocked
        frames.shadow = share.reshape(c, s, h, w).mean(axis=1).astype(np.float32)
    if passes.shaded:
        frames.images["shaded"] = radiance.reshape(c, s, h, w, 3).mean(axis=1).astype(np.float32)
    if passes.path:
        if passes.bounce_rays:
            _bounces(tracer, scene, passes, radiance, hit, points, hits.normal[hit], seed)
        frames.images["path"] = radiance.reshape(c, s, h, w, 3).mean(axis=1).astype(np.float32)
    return frames, tracer.counts
