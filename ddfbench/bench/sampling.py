"""Section 1, sampling: surface-sampling labels/s against bare open3d cast_rays rays/s on the same mesh.

The reference is bare_cast_rate below (random rays in the field box, median of 3
calls), measured right before and right after the sampler and averaged, so drift in the machine's
load hits both sides alike. Sizes: shape, s_fc, s_dr, s_p, face_mode, bare_rays.
"""

from __future__ import annotations

import time

import numpy as np
import open3d as o3d

from ddfbench.bench.context import Context, preset
from ddfbench.bench.results import SectionResult, Target, compare
from ddfbench.bench.timing import measure
from ddfbench.bench.views import incoherent_rays
from ddfbench.sampling import surface
from ddfbench.truth.oracle import open3d_scene

TARGET = Target(">=", 0.3)


def bare_cast_rate(mesh, n: int, seed: int = 0) -> float:
    """Median rays/s of open3d cast_rays over 3 calls of n incoherent rays (origins in the box, uniform directions)."""
    scene = open3d_scene(mesh)
    rays = o3d.core.Tensor(np.hstack(incoherent_rays(n, seed)))
    scene.cast_rays(rays[:1000])  # builds the BVH
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        scene.cast_rays(rays)
        times.append(time.perf_counter() - t0)
    return n / float(np.median(times))


def run(ctx: Context) -> SectionResult:
    s = ctx.sizes
    shape, oracle = ctx.shape(s["shape"]), ctx.oracle(s["shape"])
    cfg = preset("sampling", "surface", face_mode=s["face_mode"], s_fc=s["s_fc"], s_dr=s["s_dr"], s_p=s["s_p"])
    before = bare_cast_rate(shape.mesh, int(s["bare_rays"]))
    (samples, _, rejected), timing = measure(
        lambda: surface.sample(shape, oracle, cfg, "rays", np.random.default_rng(0)), ctx.repeats, warmup=0)
    after = bare_cast_rate(shape.mesh, int(s["bare_rays"]))
    bare = 0.5 * (before + after)
    labels = len(samples)
    rate = timing.rate(labels)
    row = compare("sampling", f"surface sampling labels/s ({shape.name}, {s['face_mode']} "
                  f"s_fc={s['s_fc']} s_dr={s['s_dr']} s_p={s['s_p']})", rate, "labels/s",
                  "bare open3d cast_rays rays/s (random rays in the box)", bare, device="cpu",
                  threads=ctx.threads, target=TARGET,
                  note="open3d is CPU-only: this figure is from the CPU whatever --device says")
    details = {"labels": labels, "hits": int(samples.hit.sum()), "rejected": rejected, "timing": timing.as_dict(),
               "bare_rays_per_s_before": before, "bare_rays_per_s_after": after, "faces": int(len(shape.mesh.faces))}
    return SectionResult([row], details)
