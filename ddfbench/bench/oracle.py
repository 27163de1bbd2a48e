"""Section 2, oracle: first-hit rays/s of each backend (open3d, embreex, and Warp's BVH on the CPU where
the `gpu` extra is installed) on primary and incoherent rays.

Primary rays: one pinhole camera looking at the shape (ddfbench.bench.views.view_rays): coherent,
neighbouring rays walk the same BVH nodes. Incoherent rays: origins uniform in the field box,
directions uniform on the sphere. The reference for each is open3d's bare
RaycastingScene.cast_rays on the very same rays, so the ratio of the open3d backend is what the
Oracle wrapper keeps of the bare speed, and the embreex ratio compares the two Embree bindings.
Sizes: shape, primary_px (image side), incoherent_rays.
"""

from __future__ import annotations

import importlib.util

import numpy as np
import open3d as o3d

from ddfbench.bench.context import Context
from ddfbench.bench.results import SectionResult, compare
from ddfbench.bench.timing import measure_side_by_side
from ddfbench.bench.views import incoherent_rays, view_rays
from ddfbench.truth.oracle import open3d_scene

BACKENDS = ("open3d", "embree") + (("warp",) if importlib.util.find_spec("warp") else ())


def run(ctx: Context) -> SectionResult:
    s = ctx.sizes
    shape = ctx.shape(s["shape"])
    scene = open3d_scene(shape.mesh)
    result = SectionResult(details={"faces": int(len(shape.mesh.faces))})
    for kind, (o, d) in (("primary", view_rays(int(s["primary_px"]))),
                         ("incoherent", incoherent_rays(int(s["incoherent_rays"])))):
        rays = o3d.core.Tensor(np.hstack([o, d]).astype(np.float32))
        oracles = {backend: ctx.oracle(s["shape"], backend) for backend in BACKENDS}
        fns = {"bare": lambda: scene.cast_rays(rays)}
        fns.update({backend: (lambda orc=orc: orc.first_hit(o, d)) for backend, orc in oracles.items()})
        timed = measure_side_by_side(fns, ctx.repeats, ctx.warmup)
        n, bare = len(o), timed["bare"][1]
        result.details[f"{kind}_bare_open3d"] = bare.as_dict()
        for backend in BACKENDS:
            (t, _, _), timing = timed[backend]
            result.details[f"{kind}_{backend}"] = {**timing.as_dict(), "rays": n,
                                                   "hit_share": float(np.isfinite(t).mean())}
            result.rows.append(compare(
                "oracle", f"Oracle.first_hit rays/s, backend {backend}, {kind} rays ({n})", timing.rate(n), "rays/s",
                "bare open3d cast_rays rays/s, same rays", bare.rate(n), device="cpu", threads=ctx.threads,
                note="CPU-only backends"))
    return result
