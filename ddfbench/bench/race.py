"""Section 9, the race on one device: DDF depth against a BVH and against sphere tracing, on the same rays,
in the same process, each speed with its accuracy against the oracle beside it (the DDF paper's speed
claim, measured where it is about: `--device cuda`).

Contestants (built in ddfbench.bench.contestants), all answering first-hit depth (no normals) for the same rays:
- DDF (conf/model/ddf_tuned.yaml, the preset the experiments compare, trained `fit_seconds`): ddfbench.models.ddf.infer.DDFDepth on the device in fp32,
  bf16 autocast and bf16 compiled (torch.compile; only with `compile: true`), and on CUDA with Triton the MLP
  as one kernel between compiled passes (ddf_bf16_fused) and the whole answer as one kernel
  (ddf_bf16_fused_depth), each checked against bf16 first; the rows name the fastest, as measured; beside
  it the bare network forward on the same box-entry points (what answering has to cost at least);
- Warp BVH (ddfbench.truth.warp_cast) on the same device, rays already there;
- Embree on every CPU core, numpy rays on the host: open3d's RaycastingScene through the oracle, or with
  `--oracle-backend warp` (a machine without open3d) embreex in one process per core
  (ddfbench.truth.embree_pool); the JSON's details say which;
- sphere tracing the neural SDF (conf/model/neural_sdf_tuned.yaml, trained like the DDF) and a level-set grid SDF
  (`grid_resolution`), twice: through their intersect (numpy in and out: host transfers included; "…_trace"), and
  through ddfbench.evaluate.trace_device.DeviceSphereTracer (rays and state on the device, a host sync only at
  compaction; "…_device_<precision>"), so that DDF against SDF compares methods and not implementations.
Ray sets: "primary" (one pinhole camera, `px`^2 rays, turned about the shape by `ray_seed`: bench.views.orbit_eye)
and "incoherent" (origins uniform in the field box, uniform directions, seeded by `ray_seed`): issue 51 repeats the
race in fresh processes with seeds 1-5 and pools the ratios (ddfbench.bench.repeats). Then a sweep of incoherent
ray counts (`sweep`: latency and throughput of the DDF's fastest variant, Warp and Embree) and the four DDF
capacities of the Pareto sweep (conf/experiment/pareto.yaml) on the primary rays, each beside Warp's BVH of the
shape and of its LODs (`lods`: triangle counts) on the same rays.
Networks fit for `fit_steps` steps when set (fixed work), else `fit_seconds` of wall clock; with `prepared` (a
folder) they, the grid and the LODs are saved there once and loaded by later processes (ddfbench.bench.prepared).
Cold costs (details "cold" and each contestant's cold_s): BVH builds (Warp; Embree in one process and the pool's
start), loads, and every contestant's first call (kernel compile and autotune, Warp's module load).
Accuracy: depth MAE on rays both the contestant and the reference hit, and mask IoU, against Embree on
the same rays (the open3d oracle, or with `--oracle-backend warp` the embreex pool, so that warp_bvh is
not scored against itself; Warp's own answers only where embreex is missing or `embree` is false, as details'
"reference" says). Every timed call is synchronized (ddfbench.core.clock.clock), warm-up
excluded (ddfbench.bench.timing). Absolute figures hold for the device named in the JSON's env.
Sizes: shape, px, incoherent_rays, ray_seed, sweep (ray counts), embree_max (largest sweep count Embree runs),
fit_seconds, fit_steps (0: by fit_seconds), prepared (folder or null), grid_resolution, n_samples (neural SDF
samples), chunk (DDF rays per network call), compile (bool: the DDF's torch.compile variants), sdf_compile (bool:
the neural SDF's device tracer compiled too, CUDA), sdf_eager (bool: its eager device tracers), sdf_loops (bool:
the numpy-in-and-out tracing loops), embree (bool: Embree on every core, and the reference; false: the oracle's
answers are the reference), main (bool; false: neither ray set's race of every contestant nor the sweep, and no
SDF is made: only the capacities race, each beside the BVH and the LODs; the main DDF is still loaded or fit, as its
`prepared` name identifies the runs' network, and with `embree` the pool still starts as the reference), capacities
(bool), capacity_levels (null: all; or a list, e.g. [c3, c4]), lods (triangle counts), model / neural (overrides of
the main DDF / neural SDF).
"""

from __future__ import annotations

import importlib.util
import os
from typing import Callable

import numpy as np
import torch

from ddfbench.bench.contestants import (
    answer_diff,
    ddf_variants,
    device_tracers,
    embree_all_cores,
    entry_forward,
    lod_casters,
    mlp_flops,
    pareto_ddf_capacities,
    sdf_contestants,
    sdf_depth,
    surface_labels,
    train_ddf,
)
from ddfbench.bench.context import Context
from ddfbench.bench.results import SectionResult, Target, compare, precision_of
from ddfbench.bench.timing import Timing, measure_side_by_side
from ddfbench.bench.views import incoherent_rays, orbit_eye, view_rays
from ddfbench.core.clock import timed
from ddfbench.models.ddf.infer import DDFDepth

SPEED_GOAL = Target(">=", 1e9, on="value")  # the fastest DDF variant's rays/s at 1M+ rays on an H100/H200 (issue 17)
BARE_SHARE = Target(">=", 0.8)  # the fastest DDF variant against the bare forward of the same network, same precision


def accuracy(t: np.ndarray, t_ref: np.ndarray) -> dict[str, float]:
    """Depth MAE on rays both hit, and mask IoU, of t (N,) against the oracle's t_ref (N,) (inf = miss)."""
    hit, ref = np.isfinite(t), np.isfinite(t_ref)
    both, union = hit & ref, (hit | ref).sum()
    mae = float(np.abs(t[both] - t_ref[both]).mean()) if both.any() else float("nan")
    return {"depth_mae": mae, "mask_iou": float(both.sum() / union) if union else 1.0}


def fastest(timed: dict[str, tuple], names) -> str:
    """The name among `names` with the shortest median time in timed (race's output)."""
    return min((n for n in names if n in timed), key=lambda n: timed[n][1].median_s)


def race(ctx: Context, o_np: np.ndarray, d_np: np.ndarray, contestants: dict[str, Callable]) -> dict[str, tuple]:
    """Time every contestant on the same rays; returns {name: (t numpy (N,), Timing)}.

    A contestant is fn(o_dev, d_dev, o_np, d_np) -> t (torch or numpy): device tensors are made once."""
    o, d = torch.as_tensor(o_np, device=ctx.device), torch.as_tensor(d_np, device=ctx.device)
    fns = {name: (lambda f=f: f(o, d, o_np, d_np)) for name, f in contestants.items()}
    timed = measure_side_by_side(fns, ctx.repeats, ctx.warmup, device=ctx.device)
    out = {}
    for name, (t, timing) in timed.items():
        out[name] = (t.float().cpu().numpy() if isinstance(t, torch.Tensor) else np.asarray(t, np.float32), timing)
    return out


def _rate_row(measure: str, value_t: Timing, ref_name: str, ref_t: Timing, n: int, ctx: Context,
              target: Target | None = None, note: str = ""):
    return compare("race", measure, value_t.rate(n), "rays/s", ref_name, ref_t.rate(n), device=ctx.device,
                   threads=ctx.threads, precision=precision_of(measure), target=target, note=note)


def run(ctx: Context) -> SectionResult:
    from ddfbench.truth.warp_cast import WarpCaster  # the gpu extra; the section fails with its install hint without it

    s = ctx.sizes
    shape, oracle = ctx.shape(s["shape"]), ctx.oracle(s["shape"])
    result = ctx.partial = SectionResult(details={"cpu_cores": os.cpu_count(), "ray_seed": int(s.get("ray_seed", 1))})
    if ctx.device.startswith("cuda"):
        from ddfbench.bench.fused_parts import dense_bf16_tflops

        result.details["dense_bf16_tflops"] = dense_bf16_tflops(ctx.device)
    samples = surface_labels(ctx)
    cold = result.details["cold"] = {}
    (ddf, result.details["ddf"]), cold["ddf_load_or_fit_s"] = timed(lambda: train_ddf(ctx, samples, dict(s.get("model") or {})))
    sdfs = None
    if s.get("main", True):  # only the two ray sets' race has the SDFs among its contestants
        nsdf, result.details["neural_sdf"], gsdf, result.details["grid_sdf"] = sdf_contestants(ctx)
        sdfs = (nsdf, gsdf)
    warp, cold["warp_bvh_build_s"] = timed(lambda: WarpCaster(shape.mesh.vertices, shape.mesh.faces, ctx.device))
    lods = lod_casters(ctx, shape.mesh, WarpCaster, result.details)

    (embree, pool), started_s = timed(lambda: embree_all_cores(ctx, oracle, shape.mesh, result))
    if pool is not None:  # the 16 workers' start (open3d's Embree builds inside its first cast)
        cold["embree_pool_start_s"] = started_s
    if importlib.util.find_spec("embreex") is not None:
        from ddfbench.truth.oracle import Oracle

        one = (np.array([[0.0, 0.0, -2.0]], np.float32), np.array([[0.0, 0.0, 1.0]], np.float32))
        # one process: Embree builds its BVH inside the first cast, so the scene and one ray's cast together
        cold["embree_build_and_first_ray_s"] = timed(lambda: Oracle(shape.mesh, "embree").hit_distance(*one))[1]
    reference = pool.hit_distance if pool is not None else oracle.hit_distance
    result.details["reference"] = "embreex pool" if pool is not None else f"{ctx.oracle_backend} oracle"
    try:
        primary = view_rays(int(s["px"]), eye=orbit_eye(int(s.get("ray_seed", 1))))
        if sdfs is not None:
            _race_sets(ctx, result, ddf, *sdfs, warp, primary, reference, embree)
        if s.get("capacities", True):
            capacities(ctx, samples, primary, reference, {"warp_bvh": warp, **lods}, result)
    finally:
        if pool is not None:
            pool.close()
    return result


def _race_sets(ctx: Context, result: SectionResult, ddf, nsdf, gsdf, warp, primary: tuple, reference: Callable,
               embree: dict) -> None:
    """Every contestant on the two ray sets (primary: the view's (o, d), and the seed's incoherent rays), then the
    sweep (run's body once every contestant is built); reference(o, d) -> t (N,): the depth they are scored against."""
    s, chunk, seed = ctx.sizes, int(ctx.sizes["chunk"]), int(ctx.sizes.get("ray_seed", 1))
    variants = ddf_variants(ctx, ddf, compile_too=True, details=result.details)
    tracers = device_tracers(ctx, nsdf, gsdf, result.details)
    contestants: dict[str, Callable] = {name: (lambda o, d, on, dn, f=f: f(o, d)) for name, f in {**variants, **tracers}.items()}
    contestants.update({"warp_bvh": lambda o, d, on, dn: warp.cast_torch(o, d)[0], **embree})
    if s.get("sdf_loops", True):  # the numpy-in-and-out loop the device tracers are measured against
        contestants.update({"neural_sdf_trace": lambda o, d, on, dn: sdf_depth(nsdf, on, dn),
                            "grid_sdf_trace": lambda o, d, on, dn: sdf_depth(gsdf, on, dn)})
    ray_sets = {"primary": primary, "incoherent": incoherent_rays(int(s["incoherent_rays"]), seed=seed)}
    for set_name, (o_np, d_np) in ray_sets.items():
        n = len(o_np)
        o_dev, d_dev = torch.as_tensor(o_np, device=ctx.device), torch.as_tensor(d_np, device=ctx.device)
        bare = {f"ddf_bare_{p}": (lambda o, d, on, dn, f=entry_forward(ddf, o_dev, d_dev, chunk, p): f())
                for p in ("fp32", "bf16")}  # on the set's own entry points
        timed = race(ctx, o_np, d_np, {**contestants, **bare})
        t_ref = reference(o_np, d_np)
        details = result.details.setdefault(set_name, {"rays": n})
        for name, (t, timing) in timed.items():
            details[name] = {**timing.as_dict(), "rays_per_s": timing.rate(n)}
            if not name.startswith("ddf_bare"):
                details[name].update(accuracy(t, t_ref))
            if name in tracers:  # the work of its last call (every call traces the same rays)
                details[name].update(field_evals=tracers[name].field_evals, host_syncs=tracers[name].host_syncs)
        best = fastest(timed, variants)
        fastest_sdf = {kind: fastest(timed, [n for n in tracers if n.startswith(kind)])
                       for kind in ("neural_sdf", "grid_sdf") if any(n.startswith(kind) for n in tracers)}
        details["fastest"] = {"ddf": best, **fastest_sdf}
        acc = {k: details[k] for k in ("ddf_fp32", best, "warp_bvh")}
        note = (f"DDF depth MAE {acc[best]['depth_mae']:.2e} IoU {acc[best]['mask_iou']:.3f}; "
                f"Warp MAE {acc['warp_bvh']['depth_mae']:.1e} IoU {acc['warp_bvh']['mask_iou']:.4f}")
        refs = ("warp_bvh", "embree_all_cores", *fastest_sdf.values(), "neural_sdf_trace", "grid_sdf_trace")
        for ref in (r for r in refs if r in timed):
            result.rows.append(_rate_row(f"{set_name}: DDF ({best}) rays/s", timed[best][1], f"{ref} rays/s, same rays",
                                         timed[ref][1], n, ctx, note=note if ref == "warp_bvh" else ""))
        for kind, name in ((k, v) for k, v in fastest_sdf.items() if f"{k}_trace" in timed):  # against the loop
            result.rows.append(_rate_row(
                f"{set_name}: {kind} device tracer ({name}) rays/s", timed[name][1], f"{kind}_trace (intersect, "
                "numpy in and out) rays/s, same rays", timed[f"{kind}_trace"][1], n, ctx,
                note=f"depth MAE {details[name]['depth_mae']:.2e} IoU {details[name]['mask_iou']:.3f}; loop: "
                     f"{details[f'{kind}_trace']['depth_mae']:.2e} / {details[f'{kind}_trace']['mask_iou']:.3f}"))
        bare = f"ddf_bare_{precision_of(best)}"  # the forward in the fastest variant's own precision
        result.rows.append(_rate_row(f"{set_name}: DDF ({best}) rays/s", timed[best][1],
                                     f"bare {precision_of(best)} network forward rays/s, same entry points", timed[bare][1],
                                     n, ctx, target=BARE_SHARE if ctx.device.startswith("cuda") else None))
        for name in variants:
            if name != "ddf_fp32":
                details[f"{name}_vs_fp32_depth_diff"] = answer_diff(timed[name][0], timed["ddf_fp32"][0])
        if ctx.device.startswith("cuda") and n >= 1_000_000:
            result.rows.append(compare("race", f"{set_name}: DDF ({best}) rays/s", timed[best][1].rate(n), "rays/s",
                                       "goal 1e9 rays/s (H100/H200, 1M+ rays)", 1e9, device=ctx.device,
                                       threads=ctx.threads, precision=precision_of(best), target=SPEED_GOAL))
    if any(name.startswith("ddf_bf16_fused") for name in variants):  # last tuned on the 1M incoherent rays
        from ddfbench.models.ddf.fused import config

        result.details["fused_kernel_config"] = {"mlp": config("mlp"), "depth": config("depth")}
    sweep(ctx, variants, best, warp, embree, result)


def sweep(ctx: Context, variants: dict[str, DDFDepth], best_name: str, warp, embree: dict,
          result: SectionResult) -> list[dict]:
    """Incoherent ray counts `sweep`: median latency and rays/s of the DDF's variant best_name (the fastest
    on the incoherent set), Warp and Embree (up to embree_max rays)."""
    s, rows = ctx.sizes, result.details.setdefault("sweep", [])  # filled as it goes: a stop keeps what ran
    best = variants[best_name]
    for n in (int(v) for v in s["sweep"]):
        o_np, d_np = incoherent_rays(n, seed=2)
        contestants = {best_name: lambda o, d, on, dn: best(o, d), "warp_bvh": lambda o, d, on, dn: warp.cast_torch(o, d)[0]}
        if n <= int(s["embree_max"]):
            contestants.update(embree)
        timed = race(ctx, o_np, d_np, contestants)
        row = {"rays": n}
        for name, (_, timing) in timed.items():
            row[name] = {"latency_s": timing.median_s, "iqr_s": timing.iqr_s, "rays_per_s": timing.rate(n)}
        rows.append(row)
        result.rows.append(_rate_row(f"sweep {n} rays: DDF ({best_name}) rays/s", timed[best_name][1],
                                     "warp_bvh rays/s, same rays", timed["warp_bvh"][1], n, ctx))
        if ctx.device.startswith("cuda"):
            torch.cuda.empty_cache()
    return rows


def capacities(ctx: Context, samples, primary, reference: Callable, meshes: dict, result: SectionResult) -> dict[str, dict]:
    """The Pareto sweep's four DDF capacities, each fit like the main DDF: rays/s (fp32, bf16 and on CUDA the
    one-kernel depth where the network fits it; not compiled: a compile per network costs more device time than
    it tells) and accuracy, raced beside `meshes` ({name: WarpCaster}: the shape's BVH and its LODs) on the same
    rays, so every ratio to the BVH is measured side by side; the rows name the fastest bf16 variant. On CUDA
    also the fastest variant's TFLOP/s (mlp_flops) and its share of the dense bf16 product's rate."""
    o_np, d_np = primary
    n = len(o_np)
    t_ref, out = reference(o_np, d_np), result.details.setdefault("capacities", {})  # filled as it goes
    casts = {name: (lambda o, d, on, dn, c=c: c.cast_torch(o, d)[0]) for name, c in meshes.items()}
    chosen = ctx.sizes.get("capacity_levels")  # None: all four
    for level, overrides in pareto_ddf_capacities().items():
        if chosen is not None and level not in chosen:
            continue
        rep, info = train_ddf(ctx, samples, overrides)
        variants = {name: (lambda o, d, on, dn, f=f: f(o, d)) for name, f in ddf_variants(ctx, rep, False).items()}
        timed = race(ctx, o_np, d_np, {**variants, **casts})
        out[level] = {**info, "flops_per_ray": mlp_flops(rep),
                      **{name: {"rays_per_s": timing.rate(n), "cold_s": timing.cold_s, **accuracy(t, t_ref)}
                         for name, (t, timing) in timed.items()}}
        best = fastest(timed, [name for name in variants if name != "ddf_fp32"])
        out[level]["fastest"] = best
        if "dense_bf16_tflops" in result.details:
            tflops = timed[best][1].rate(n) * out[level]["flops_per_ray"] / 1e12
            out[level]["tflops"], out[level]["share_of_dense_bf16"] = tflops, tflops / result.details["dense_bf16_tflops"]
        note = f"depth MAE {out[level][best]['depth_mae']:.2e}, IoU {out[level][best]['mask_iou']:.3f}"
        for ref, label in (("ddf_fp32", "same network fp32"), *((m, f"{m} (Warp) beside it") for m in casts)):
            result.rows.append(compare("race", f"capacity {level} ({info['width']}x{info['depth']}): DDF ({best}) rays/s",
                                       timed[best][1].rate(n), "rays/s", f"{label} rays/s", timed[ref][1].rate(n),
                                       device=ctx.device, threads=ctx.threads, precision=precision_of(best),
                                       note=note if ref == "ddf_fp32" else f"{ref} depth MAE {out[level][ref]['depth_mae']:.2e}"))
    return out
