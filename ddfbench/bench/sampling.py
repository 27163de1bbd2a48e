"""Section 1, sampling: surface-sampling labels/s against bare open3d cast_rays rays/s on the same mesh.

The reference is ddfbench.sampling.bench.bare_cast_rate (random rays in the field box, median of 3
calls), measured right before and right after the sampler and averaged, so drift in the machine's
load hits both sides alike. Sizes: shape, s_fc, s_dr, s_p, face_mode, bare_rays.
"""

from __future__ import annotations

import numpy as np

from ddfbench.bench.context import DOMAIN, Context, preset
from ddfbench.bench.results import SectionResult, Target, compare
from ddfbench.bench.timing import measure
from ddfbench.sampling import surface
from ddfbench.sampling.bench import bare_cast_rate

TARGET = Target(">=", 0.3)


def run(ctx: Context) -> SectionResult:
    s = ctx.sizes
    shape, oracle = ctx.shape(s["shape"]), ctx.oracle(s["shape"])
    cfg = preset("sampling", "surface", face_mode=s["face_mode"], s_fc=s["s_fc"], s_dr=s["s_dr"], s_p=s["s_p"])
    before = bare_cast_rate(shape.mesh, int(s["bare_rays"]), DOMAIN)
    (samples, _, rejected), timing = measure(
        lambda: surface.sample(shape, oracle, cfg, "rays", np.random.default_rng(0)), ctx.repeats, warmup=0)
    after = bare_cast_rate(shape.mesh, int(s["bare_rays"]), DOMAIN)
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
