"""Render any family through the same code, compute only the effects a scene asks for, and report
what the image costs (time, rays, field evaluations) and how wrong it is (against the oracle render).

The renderer knows only `Representation.intersect`; every query passes the counting layer.

Which passes each preset (conf/scene/) triggers, by `scene.plan_passes`; N = cameras·W·H·spp (cameras·W·H
for a scene without shaded or path, whose outputs read the pixel-centre sample alone):

| preset     | outputs                                  | primary | normals | shadow rays         | bounce rays                 |
|------------|------------------------------------------|---------|---------|---------------------|-----------------------------|
| depth      | depth, mask                              | N       | no      | 0                   | 0                           |
| normals    | depth, mask, normal                      | N       | yes     | 0                   | 0                           |
| shaded     | depth, mask, normal, shaded, shadow      | N       | yes     | ≤ 1 per hit·light   | 0                           |
| path       | depth, mask, normal, path, shadow        | N       | yes     | ≤ 1 per vertex·light | 1 per live path per bounce |
| paper_fig4 | depth, mask, normal, shaded, path, shadow | N      | yes     | ≤ 1 per vertex·light | 1 per live path per bounce |

A shadow ray is cast only toward a light in front of the surface (cos θ > 0), and shaded and path
images share the shadow rays of the primary hits. Without `normal`, `shaded` or `path` in the
outputs no normal is asked for, so a DDF runs no backward pass.
"""

from __future__ import annotations

import os
from typing import Any, Mapping

from ddfbench.core.clock import compute_threads
from ddfbench.core.representation import Budget, FitData, Representation
from ddfbench.render.compare import image_metrics
from ddfbench.render.images import write_renders
from ddfbench.render.integrator import Frames, render
from ddfbench.render.scene import Scene, parse_scene, plan_passes
from ddfbench.render.timing import RenderTiming, time_renders

__all__ = ["render_scene", "render", "parse_scene", "plan_passes", "Frames", "Scene", "mesh_reference"]


def mesh_reference(mesh, domain: float, device: str = "cpu", backend: str = "open3d", faces: int = 0) -> Representation:
    """The full GT mesh (trimesh) as the mesh family, cast by `backend` (the oracle's: open3d | embree |
    warp, Warp's BVH on `device`): what render_scene compares a family's frames with. faces > 0: its
    simplification to that many faces (a LOD, as the mesh family's `faces` builds it)."""
    from ddfbench.models import load_family

    reference = load_family("mesh")({"faces": int(faces), "backend": backend}, domain=domain)
    reference.fit(FitData(samples=None, mesh=mesh, oracle=None), Budget(device=device))
    return reference


def _timed_render(rep: Representation, scene: Scene, seed: int) -> tuple[Frames, dict[str, int], RenderTiming]:
    passes = plan_passes(scene)
    (frames, counts), timing = time_renders(lambda: render(rep, scene, passes, seed), scene.repeats, scene.warmup,
                                         scene.timing_max_seconds)
    return frames, counts, timing


def _rays(counts: Mapping[str, int]) -> int:
    return int(counts["primary_rays"] + counts["shadow_rays"] + counts["bounce_rays"])


def _renders_folder(out_dir: str) -> str:
    """out_dir is the run folder (renders go below it) or already the renders folder."""
    return out_dir if os.path.basename(os.path.normpath(out_dir)) == "renders" else os.path.join(out_dir, "renders")


def render_scene(rep: Representation, reference: Representation, scene_cfg: Mapping[str, Any], out_dir: str,
                 seed: int) -> dict[str, Any]:
    """Render `rep` and the oracle `reference` (the GT mesh family, mesh_reference) with the same cameras and samples.

    Returns {"metrics": image accuracy (compare.py), "cost": render timings and rays/s of rep and of
    the reference, "counts": the work of rep's cold render, "artifacts": the renders folder relative
    to the run folder}. Writes arrays and PNGs (images.py) into the renders folder.
    """
    scene = parse_scene(scene_cfg)
    frames, counts, timing = _timed_render(rep, scene, seed)
    ref_frames, ref_counts, ref_timing = _timed_render(reference, scene, seed)
    folder = _renders_folder(out_dir)
    write_renders(folder, ref_frames, frames, scene.outputs)
    rays_per_s = _rays(counts) / timing.warm_s if timing.warm_s > 0 else 0.0
    ref_rays_per_s = _rays(ref_counts) / ref_timing.warm_s if ref_timing.warm_s > 0 else 0.0
    cost = {
        "render_cold_s": timing.cold_s,
        "render_warm_s": timing.warm_s,
        "render_warm_iqr_s": timing.warm_iqr_s,
        "rays_per_s": rays_per_s,
        "render_repeats": timing.repeats,
        "render_warmups": timing.warmups,
        "render_threads": compute_threads(),
        "reference_render_cold_s": ref_timing.cold_s,
        "reference_render_warm_s": ref_timing.warm_s,
        "reference_rays_per_s": ref_rays_per_s,
        "reference_threads": reference.cast_threads(),  # the reference BVH's CPU threads (None: warp's device)
        # warm-render speed of rep relative to the oracle's BVH, measured in this process (DESIGN: ratios)
        "render_speed_vs_reference": ref_timing.warm_s / timing.warm_s if timing.warm_s > 0 else 0.0,
    }
    return {
        "metrics": image_metrics(ref_frames, frames, scene.outputs),
        "cost": cost,
        "counts": dict(counts),
        "artifacts": os.path.relpath(folder, os.path.dirname(os.path.normpath(folder))),
    }
