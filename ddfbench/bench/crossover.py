"""Section 12, the triangle-count crossover: a BVH's time per ray as the mesh grows, against a DDF's, whose
cost does not depend on the mesh (the DDF paper's premise, measured).

Meshes: the sizes' shape decimated (quadric edge collapse, ddfbench.models.mesh.decimate) to the smaller
counts and subdivided (midpoint: four triangles a triangle, the same surface) to the larger ones, so a count
above the shape's own changes the BVH's work and not the geometry. Rays: the same primary rays (one pinhole
view, ddfbench.bench.views) and incoherent rays (origins in the field box) for every mesh.

Per mesh and ray set, measured side by side in one process on the same rays: the BVH (the oracle's open3d
RaycastingScene, Embree inside, every core) answering first-hit distances, and each DDF preset of the sizes
(untrained weights: a forward's cost does not depend on their values; every ray visible, as in section 3)
answering depth without normals. Also per mesh: the BVH's cold call (scene build + first cast) and the depth
error of the mesh against the shape's own mesh on the same rays (a LOD's price). The crossover is the count
where the BVH's time per ray meets the DDF's, interpolated log-log between the two counts that bracket it.
Sizes: shape, counts (triangles), px (image side), incoherent_rays, models (DDF presets).
"""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
import trimesh

from ddfbench.bench.context import Context
from ddfbench.bench.ddf import make_ddf
from ddfbench.bench.results import SectionResult, compare
from ddfbench.bench.timing import measure_side_by_side
from ddfbench.bench.views import incoherent_rays, view_rays
from ddfbench.models.mesh import decimate
from ddfbench.truth.oracle import Oracle


def mesh_with_faces(mesh: trimesh.Trimesh, faces: int) -> trimesh.Trimesh:
    """mesh with about `faces` triangles: decimated below its own count, midpoint-subdivided (x4 per pass, the
    same surface) until it has at least `faces` above it."""
    if faces <= len(mesh.faces):
        return decimate(mesh, faces)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    while len(f) < faces:
        v, f = trimesh.remesh.subdivide(v, f)
    return trimesh.Trimesh(v, f, process=False)


def crossover(counts: Sequence[float], ratios: Sequence[float]) -> float | None:
    """The count where ratio (BVH time / DDF time per ray) first crosses 1, interpolated linearly in log count
    and log ratio between the two counts that bracket it (counts ascending); None when no pair brackets 1."""
    for (c0, r0), (c1, r1) in zip(zip(counts, ratios), zip(counts[1:], ratios[1:])):
        if (r0 - 1.0) * (r1 - 1.0) <= 0 and r0 != r1:
            share = -math.log(r0) / (math.log(r1) - math.log(r0))
            return math.exp(math.log(c0) + share * (math.log(c1) - math.log(c0)))
    return None


def depth_error(t: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """Mean |t - reference| on rays both hit, and the share of rays whose hit or miss differs."""
    both = np.isfinite(t) & np.isfinite(reference)
    return {"depth_mae": float(np.abs(t[both] - reference[both]).mean()) if both.any() else math.nan,
            "hit_flip_share": float((np.isfinite(t) != np.isfinite(reference)).mean())}


def run(ctx: Context) -> SectionResult:
    s = ctx.sizes
    base = ctx.shape(s["shape"]).mesh
    ray_sets = {"primary": view_rays(int(s["px"])), "incoherent": incoherent_rays(int(s["incoherent_rays"]), seed=1)}
    ddfs = {name: make_ddf({}, ctx.device, name) for name in s["models"]}
    reference = Oracle(base, backend="open3d")
    truth = {kind: reference.hit_distance(*rays) for kind, rays in ray_sets.items()}
    result = SectionResult(details={"shape": s["shape"], "shape_faces": len(base.faces), "counts": [],
                                    "rays": {k: len(o) for k, (o, _) in ray_sets.items()},
                                    "models": {n: {"n_params": r.n_params(), "width": r.cfg["width"],
                                                   "depth": r.cfg["depth"]} for n, r in ddfs.items()}})
    ctx.partial = result
    per_ray: dict[tuple[str, str], list[float]] = {}
    for target in s["counts"]:
        mesh = mesh_with_faces(base, int(target))
        bvh = Oracle(mesh, backend="open3d")
        faces = len(mesh.faces)
        result.details["counts"].append(faces)
        for kind, (o, d) in ray_sets.items():
            fns = {"bvh": lambda o=o, d=d: bvh.hit_distance(o, d)}
            fns.update({name: (lambda r=r, o=o, d=d: r.intersect(o, d, normals=False)) for name, r in ddfs.items()})
            timed = measure_side_by_side(fns, ctx.repeats, ctx.warmup, device=ctx.device)
            t_bvh, bvh_t = timed["bvh"]
            entry = {"faces": faces, "bvh": bvh_t.as_dict(), **depth_error(t_bvh, truth[kind])}
            per_ray.setdefault(("bvh", kind), []).append(bvh_t.median_s / len(o))
            for name in ddfs:
                ddf_t = timed[name][1]
                entry[name] = ddf_t.as_dict()
                per_ray.setdefault((name, kind), []).append(ddf_t.median_s / len(o))
                result.rows.append(compare(
                    "crossover", f"{name} DDF depth rays/s, {kind} rays", ddf_t.rate(len(o)), "rays/s",
                    f"BVH (open3d Embree, every core) on {faces:,} triangles, same rays", bvh_t.rate(len(o)),
                    device=ctx.device, threads=ctx.threads,
                    note="above 1: the DDF answers faster than the BVH of this mesh"))
            result.details.setdefault(kind, []).append(entry)
    counts = result.details["counts"]
    for kind in ray_sets:
        bvh = per_ray[("bvh", kind)]
        for name in ddfs:
            ratios = [b / m for b, m in zip(bvh, per_ray[(name, kind)])]
            found = crossover(counts, ratios)
            result.details.setdefault("crossover", {})[f"{name}, {kind}"] = {
                "triangles": found, "bvh_over_ddf": ratios, "ddf_seconds_per_ray": per_ray[(name, kind)],
                "bvh_seconds_per_ray": bvh}
            result.notes.append(
                f"{name}, {kind} rays: BVH / DDF time per ray {ratios[0]:.3g} at {counts[0]:,} triangles to "
                f"{ratios[-1]:.3g} at {counts[-1]:,}; DDF {min(per_ray[(name, kind)]) * 1e6:.3g}-"
                f"{max(per_ray[(name, kind)]) * 1e6:.3g} µs a ray, BVH {bvh[0] * 1e6:.3g}-{bvh[-1] * 1e6:.3g} µs; "
                + (f"crossover at {found:,.0f} triangles" if found else "no crossover in this range"))
    for i, faces in enumerate(counts):
        primary = result.details["primary"][i]
        result.notes.append(
            f"{faces:,} triangles: BVH build + first cast {primary['bvh']['cold_s']:.3g} s ({len(ray_sets['primary'][0]):,} "
            f"primary rays); depth MAE against the shape's own mesh {primary['depth_mae']:.2e} (primary), "
            f"{result.details['incoherent'][i]['depth_mae']:.2e} (incoherent); rays that flip hit/miss "
            f"{primary['hit_flip_share']:.2%}")
    return result
