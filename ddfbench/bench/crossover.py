"""Section 12, the triangle-count crossover: a BVH's time per ray as the mesh grows, against a DDF's, whose
cost does not depend on the mesh (the DDF paper's premise, measured).

Meshes: the sizes' shape decimated (quadric edge collapse, ddfbench.models.mesh.decimate: pymeshlab) to the
smaller counts and subdivided (midpoint: four triangles a triangle, the same surface) to the larger ones, so a
count above the shape's own changes the BVH's work and not the geometry. With `prepared` (a folder) every
decimated mesh is saved there once and loaded by later runs (ddfbench.bench.prepared.mesh, the race's LOD
files), so a machine without pymeshlab (a lent GPU) runs on the LODs a CPU run made; subdivision is trimesh's,
made where it runs (a 3.6M-triangle mesh is 123 MiB on disk). Rays: the same primary rays (one pinhole view,
ddfbench.bench.views) and incoherent rays (origins in the field box) for every mesh.

Per mesh and ray set, measured side by side in one process on the same rays: a BVH answering first-hit
distances, and each DDF preset of the sizes (untrained weights: a forward's cost does not depend on their
values; every ray visible, as in section 3) answering depth without normals. Two backends, by the oracle's
(`--oracle-backend`):
- open3d (the default; the committed CPU report): the oracle's open3d RaycastingScene (Embree inside, every
  core) and DDF.intersect, numpy rays in and out;
- warp (a machine without open3d, e.g. `--device cuda`): Warp's BVH (ddfbench.truth.warp_cast.WarpCaster) on
  the device and the DDF's device path (ddfbench.models.ddf.infer.DDFDepth), both on device tensors made once
  per ray set: on CUDA with Triton the one-kernel depth (fused="depth", checked against the bf16 forward first;
  bf16 where it fails or the network does not fit it, e.g. the line grid's), else bf16 on CUDA, fp32 on the
  CPU. The details name the BVH and every preset's variant.
Also per mesh: the BVH's cold cost (build + first cast: open3d builds its scene inside the first cast; Warp's
build is timed apart, in details bvh_build_s) and the depth error of the mesh against the shape's own mesh
(the same backend's answer) on the same rays (a LOD's price). The crossover is the count where the BVH's time
per ray meets the DDF's, interpolated log-log between the two counts that bracket it.
Sizes: shape, counts (triangles), px (image side), incoherent_rays, models (DDF presets), prepared (folder or
null).
"""

from __future__ import annotations

import dataclasses
import importlib.util
import math
import os
from typing import Any, Callable, Sequence

import numpy as np
import torch
import trimesh

from ddfbench.bench import prepared
from ddfbench.bench.context import Context
from ddfbench.bench.ddf import make_ddf
from ddfbench.bench.results import SectionResult, compare
from ddfbench.bench.timing import measure_side_by_side
from ddfbench.bench.views import incoherent_rays, view_rays
from ddfbench.core.clock import timed
from ddfbench.core.errors import one_line
from ddfbench.models.ddf import DDF
from ddfbench.models.ddf.infer import DDFDepth
from ddfbench.models.mesh import decimate
from ddfbench.truth.oracle import Oracle

CHUNK = 1 << 21  # DDFDepth's rays per network call: a 1M-ray set in one call, activations bounded beyond it
OPEN3D_BVH = "open3d Embree, every core"


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


def ddf_depth(rep: DDF, device: str, fused: bool | None = None) -> tuple[DDFDepth, str]:
    """rep's device path and its name: with fused (default: on CUDA with Triton) the one-kernel depth
    (fused="depth"), checked once against the bf16 forward (contestants.check_against), else the bf16 forward with
    why; on CUDA without Triton bf16, on the CPU fp32."""
    cuda = device.startswith("cuda")
    if fused is None:
        fused = cuda and importlib.util.find_spec("triton") is not None
    if not fused:
        if not cuda:
            return DDFDepth(rep, "fp32", chunk=CHUNK), "DDFDepth fp32"
        return DDFDepth(rep, "bf16", chunk=CHUNK), "DDFDepth bf16 (fused depth not run: Triton is not installed)"
    bf16 = DDFDepth(rep, "bf16", chunk=CHUNK)
    try:
        from ddfbench.bench.contestants import check_against

        one_kernel = DDFDepth(rep, "bf16", fused="depth", chunk=CHUNK)
        check_against(one_kernel, bf16, device)
    except Exception as err:  # the bench goes on with the bf16 forward; the details say why
        return bf16, f"DDFDepth bf16 (fused depth not run: {one_line(err)})"
    return one_kernel, "DDFDepth bf16 fused depth (one kernel)"


def _host(t: Any) -> np.ndarray:
    """A BVH's answer (torch tensor or numpy array) as a numpy array on the host."""
    return t.float().cpu().numpy() if isinstance(t, torch.Tensor) else np.asarray(t)


def run(ctx: Context) -> SectionResult:
    s = ctx.sizes
    shape = s["shape"]
    base = ctx.shape(shape).mesh
    ray_sets = {"primary": view_rays(int(s["px"])), "incoherent": incoherent_rays(int(s["incoherent_rays"]), seed=1)}
    ddfs = {name: make_ddf({}, ctx.device, name) for name in s["models"]}
    warp = ctx.oracle_backend == "warp"
    if warp:  # Warp's BVH and the DDF's device path, on device tensors made once per ray set
        from ddfbench.truth.warp_cast import WarpCaster  # the gpu extra

        rays = {kind: tuple(torch.as_tensor(a, device=ctx.device) for a in r) for kind, r in ray_sets.items()}
        answers, variants = {}, {}
        for name, rep in ddfs.items():
            answers[name], variants[name] = ddf_depth(rep, ctx.device)
        bvh_name = f"Warp BVH ({torch.device(ctx.device).type})"

        def build(mesh: trimesh.Trimesh) -> tuple[dict[str, Callable], float | None]:
            caster, seconds = timed(lambda: WarpCaster(mesh.vertices, mesh.faces, ctx.device))  # it synchronizes
            return {kind: (lambda o=o, d=d: caster.cast_torch(o, d)[0]) for kind, (o, d) in rays.items()}, seconds

        ddf_fns = {kind: {name: (lambda f=f, o=o, d=d: f(o, d)) for name, f in answers.items()}
                   for kind, (o, d) in rays.items()}
    else:  # open3d's Embree on every core and DDF.intersect, numpy in and out (the committed CPU report)
        variants = {name: "DDF.intersect fp32 (numpy in and out)" for name in ddfs}
        bvh_name = OPEN3D_BVH

        def build(mesh: trimesh.Trimesh) -> tuple[dict[str, Callable], float | None]:
            bvh = Oracle(mesh, backend="open3d")  # the scene's BVH is built in its first cast
            return {kind: (lambda o=o, d=d: bvh.hit_distance(o, d)) for kind, (o, d) in ray_sets.items()}, None

        ddf_fns = {kind: {name: (lambda r=r, o=o, d=d: r.intersect(o, d, normals=False)) for name, r in ddfs.items()}
                   for kind, (o, d) in ray_sets.items()}
    truth = {kind: _host(cast()) for kind, cast in build(base)[0].items()}  # the shape's own mesh, same backend
    result = SectionResult(details={"shape": shape, "shape_faces": len(base.faces), "counts": [], "bvh": bvh_name,
                                    "rays": {k: len(o) for k, (o, _) in ray_sets.items()},
                                    "models": {n: {"n_params": r.n_params(), "width": r.cfg["width"],
                                                   "depth": r.cfg["depth"], "variant": variants[n]}
                                               for n, r in ddfs.items()}})
    if warp:
        result.details["bvh_build_s"] = []
    ctx.partial = result
    precision = {name: "bf16" if "bf16" in variants[name] else "fp32" for name in ddfs}
    per_ray: dict[tuple[str, str], list[float]] = {}
    for target in (int(c) for c in s["counts"]):
        mesh = (prepared.mesh(s, f"{shape}-lod", {"shape": shape, "faces": target}, lambda t=target: decimate(base, t))
                if target < len(base.faces) else mesh_with_faces(base, target))  # subdividing needs no pymeshlab
        casts, build_s = build(mesh)
        faces = len(mesh.faces)
        result.details["counts"].append(faces)
        if build_s is not None:
            result.details["bvh_build_s"].append(build_s)
        for kind, (o, d) in ray_sets.items():
            timed_fns = measure_side_by_side({"bvh": casts[kind], **ddf_fns[kind]}, ctx.repeats, ctx.warmup,
                                             device=ctx.device)
            t_bvh, bvh_t = timed_fns["bvh"]
            if not warp:  # open3d's Embree casts on every core whatever torch's threads: its figure says so
                bvh_t = dataclasses.replace(bvh_t, threads=os.cpu_count() or 1)
            entry = {"faces": faces, "bvh": bvh_t.as_dict(), **depth_error(_host(t_bvh), truth[kind])}
            per_ray.setdefault(("bvh", kind), []).append(bvh_t.median_s / len(o))
            for name in ddfs:
                ddf_t = timed_fns[name][1]
                entry[name] = ddf_t.as_dict()
                per_ray.setdefault((name, kind), []).append(ddf_t.median_s / len(o))
                result.rows.append(compare(
                    "crossover", f"{name} DDF depth rays/s, {kind} rays", ddf_t.rate(len(o)), "rays/s",
                    f"BVH ({bvh_name}) on {faces:,} triangles, same rays", bvh_t.rate(len(o)),
                    device=ctx.device, threads=ctx.threads, precision=precision[name],
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
    if warp:
        result.notes.append(f"BVH: {bvh_name}; DDF: " + "; ".join(f"{n}: {v}" for n, v in variants.items()))
    for i, faces in enumerate(counts):
        primary = result.details["primary"][i]
        cold, build_text = primary["bvh"]["cold_s"], ""
        if warp:  # Warp builds in its constructor (timed apart), open3d inside its first cast
            cold += result.details["bvh_build_s"][i]
            build_text = f"; build {result.details['bvh_build_s'][i]:.3g} s"
        result.notes.append(
            f"{faces:,} triangles: BVH build + first cast {cold:.3g} s ({len(ray_sets['primary'][0]):,} "
            f"primary rays{build_text}); depth MAE against the shape's own mesh {primary['depth_mae']:.2e} (primary), "
            f"{result.details['incoherent'][i]['depth_mae']:.2e} (incoherent); rays that flip hit/miss "
            f"{primary['hit_flip_share']:.2%}")
    return result
