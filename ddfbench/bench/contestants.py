"""The race's contestants (ddfbench.bench.race), built or loaded on the section's device: the DDF and its
Pareto capacities (fit by the sizes' budget or loaded from `prepared`), its variants (fp32, bf16, compiled, the
fused kernels, each checked against bf16 first), the neural and grid SDF with their device-resident tracers (each
checked first), the shape's LODs as Warp BVHs, and Embree on every core; plus the checks and the per-ray answer
comparisons they share with the crossover section.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
from typing import Callable

import numpy as np
import torch

from ddfbench.bench import prepared
from ddfbench.bench.context import Context, model_preset, preset
from ddfbench.bench.ddf import bare_forward
from ddfbench.bench.results import SectionResult
from ddfbench.bench.tracing import grid_sdf, neural_sdf
from ddfbench.bench.views import incoherent_rays
from ddfbench.core import plugins
from ddfbench.core.clock import clock, timed
from ddfbench.core.errors import InputError, one_line
from ddfbench.core.geometry import box_entry
from ddfbench.evaluate.trace_device import DeviceSphereTracer
from ddfbench.models.ddf import DDF
from ddfbench.models.ddf.infer import DDFDepth
from ddfbench.models.grid_sdf import GridSDF
from ddfbench.models.mesh import decimate
from ddfbench.models.neural_sdf import NeuralSDF
from ddfbench.sampling import surface
from ddfbench.truth.embree_pool import EmbreePool

DDF_PRESET = "ddf_tuned"  # the DDF of representations, render_time and pareto
SDF_PRESET = "neural_sdf_tuned"  # the neural SDF beside it there
TF32_EPS_ABS = 1e-4  # the device tracer's absolute hit tolerance in tf32 (see device_tracers)


def pareto_ddf_capacities() -> dict[str, dict]:
    """The DDF's pareto levels (its YAML's experiments.pareto): {"c1": model overrides, ...}."""
    levels = plugins.levels("model", DDF_PRESET, "pareto")
    return {level: dict(part.get("model") or {}) for level, part in levels.items()}


def surface_labels(ctx: Context) -> Callable:
    """() -> the sizes' shape's surface-sampled DDF labels (conf/sampling/surface.yaml, seed 0), drawn on the first
    call only: a network loaded from `prepared` needs none."""
    shape, oracle = ctx.shape(ctx.sizes["shape"]), ctx.oracle(ctx.sizes["shape"])
    return functools.cache(
        lambda: surface.sample(shape, oracle, preset("sampling", "surface"), "rays", np.random.default_rng(0))[0])


def train_ddf(ctx: Context, samples: Callable, overrides: dict) -> tuple[DDF, dict]:
    """conf/model/<DDF_PRESET>.yaml with overrides, fit on samples() by the sizes' budget (Context.timed_fit), or
    loaded from the sizes' `prepared` folder; on ctx.device."""
    fresh = DDF(model_preset(DDF_PRESET, **overrides))  # its cfg holds the family's defaults too

    def make() -> tuple[DDF, dict]:
        return fresh, {**ctx.timed_fit(fresh, samples()), "n_params": fresh.n_params(),
                       **{k: fresh.cfg[k] for k in ("width", "depth")}}

    rep, info = prepared.artifact(ctx.sizes, f"{DDF_PRESET}-{fresh.cfg['width']}x{fresh.cfg['depth']}",
                                  {"cfg": fresh.cfg, "labels": "surface sampling, exact", **ctx.fit_spec()}, DDF, make)
    return rep.to(ctx.device), info


def sdf_contestants(ctx: Context) -> tuple[NeuralSDF, dict, GridSDF, dict]:
    """The neural SDF (SDF_PRESET, the sizes' `neural` overrides, fit like the DDF) and the level-set grid SDF, made
    or loaded from `prepared` (bench.prepared), on ctx.device: (neural, its info, grid, its info)."""
    s = ctx.sizes
    cfg = model_preset(SDF_PRESET, **dict(s.get("neural") or {}))
    nsdf, n_info = prepared.artifact(s, SDF_PRESET, {"cfg": cfg, "n_samples": s["n_samples"], **ctx.fit_spec()},
                                     NeuralSDF, lambda: neural_sdf(ctx, SDF_PRESET))
    gsdf, g_info = prepared.artifact(s, "grid_sdf", {"cfg": model_preset("grid_sdf"), "shape": s["shape"],
                                                     "resolution": s["grid_resolution"], "build": "levelset"},
                                     GridSDF, lambda: grid_sdf(ctx))
    return nsdf.to(ctx.device), n_info, gsdf.to(ctx.device), g_info


def device_tracers(ctx: Context, nsdf: NeuralSDF, gsdf: GridSDF, details: dict) -> dict[str, DeviceSphereTracer]:
    """Both SDFs through the device-resident tracer with their presets' trace options: the neural SDF in fp32 and
    bf16 (on CUDA also tf32, and with `sdf_compile` its step compiled in tf32), the grid in fp32 (trilinear reads).
    Each traces 4096 incoherent rays first: one that fails is left out with why in details[name], and the seconds
    of that first call (a compile) go to details["cold"][f"{name}_first_4096_rays_s"]."""
    cuda = ctx.device.startswith("cuda")
    # tf32 rounds the field by about 1e-4, above the preset's 1e-6 hit tolerance: it gets TF32_EPS_ABS (named in
    # details), as bf16 gets the tracer's eps_abs_bf16
    tf32_opts = dataclasses.replace(nsdf.trace_options, eps_abs=max(TF32_EPS_ABS, nsdf.trace_options.eps_abs))
    eager = (["fp32", "tf32", "bf16"] if cuda else ["fp32", "bf16"]) if ctx.sizes.get("sdf_eager", True) else []
    made = {f"neural_sdf_device_{p}": DeviceSphereTracer(nsdf.field, nsdf.domain,
                                                         tf32_opts if p == "tf32" else nsdf.trace_options, precision=p)
            for p in eager}
    if cuda and ctx.sizes.get("sdf_compile"):
        made["neural_sdf_device_tf32_compiled"] = DeviceSphereTracer(nsdf.field, nsdf.domain, tf32_opts,
                                                                     precision="tf32", compiled=True)
    details["device_tracer_eps_abs"] = {name: t.eps_abs for name, t in made.items()}
    made["grid_sdf_device_fp32"] = DeviceSphereTracer(gsdf.field, gsdf.domain, gsdf.trace_options)
    o, d = (torch.as_tensor(a, device=ctx.device) for a in incoherent_rays(4096, seed=5))
    out, first = {}, {}
    for name, tracer in made.items():
        try:
            t, details.setdefault("cold", {})[f"{name}_first_4096_rays_s"] = timed(lambda: tracer(o, d))
            first[name] = t.cpu().numpy()
            reference = first.get("neural_sdf_device_fp32") if name.startswith("neural") else None  # (when raced)
            if reference is not None and name != "neural_sdf_device_fp32":  # tf32, bf16, compiled: as fp32 answers
                diff = answer_diff(first[name], reference)
                if diff["mask_disagreement"] > 0.02:
                    raise ValueError(f"hit masks disagree with the fp32 tracer's on {diff['mask_disagreement']:.3f}")
                details[f"{name}_vs_fp32_on_4096_rays"] = diff
            out[name] = tracer
        except Exception as err:  # the race goes on without it; the JSON says why
            details[name] = f"not run: {one_line(err)}"
    return out


def prepared_lod(sizes: dict, mesh, faces: int):
    """The sizes' shape `mesh` decimated to `faces` triangles (trimesh), from sizes' `prepared` folder when there, else
    made (pymeshlab) and saved there."""
    return prepared.mesh(sizes, f"{sizes['shape']}-lod", {"shape": sizes["shape"], "faces": faces},
                         lambda: decimate(mesh, faces))


def lod_casters(ctx: Context, mesh, caster: Callable, details: dict) -> dict[str, Callable]:
    """{"mesh_lod_<faces>": Warp caster of the shape decimated to `lods` triangles}, the LODs from `prepared` when
    there (a machine without pymeshlab cannot decimate: then {} and why in details["lods"])."""
    out = {}
    for faces in (int(f) for f in ctx.sizes.get("lods") or []):
        try:
            lod = prepared_lod(ctx.sizes, mesh, faces)
        except InputError as err:
            details["lods"] = f"not run: {err}"
            return {}
        out[f"mesh_lod_{len(lod.faces)}"] = caster(lod.vertices, lod.faces, ctx.device)
    return out


def mlp_flops(rep: DDF) -> int:
    """Multiply-adds x 2 of one ray through the network's Linear layers (unpadded: what the network needs)."""
    return 2 * sum(m.in_features * m.out_features for m in rep.net.modules() if isinstance(m, torch.nn.Linear))


def entry_forward(rep: DDF, o: torch.Tensor, d: torch.Tensor, chunk: int, precision: str) -> Callable[[], None]:
    """The network alone (bench.ddf.bare_forward) on the box-entry points of rays o, d (N, 3) (computed once,
    outside the timing), in fp32 or under bf16 autocast."""
    x = o + box_entry(o, d, rep.domain)[0][:, None] * d
    dtype = torch.bfloat16 if precision == "bf16" else None
    return lambda: bare_forward(rep.net, x, d, chunk, dtype=dtype)


def ddf_variants(ctx: Context, rep: DDF, compile_too: bool, details: dict | None = None) -> dict[str, DDFDepth]:
    """fp32, bf16, with compile_too and sizes `compile` bf16 compiled and, on CUDA with Triton, the fused kernels
    of ddfbench.models.ddf.fused: with compile_too the MLP kernel between compiled passes (ddf_bf16_fused) and always
    the one-kernel depth (ddf_bf16_fused_depth). A variant that cannot be built or answers 4096 rays unlike bf16
    is left out, with why in details[name]; the seconds of a fused variant's build and check (its kernels'
    compile and a first autotune) go to details["cold"][f"{name}_build_and_check_s"]."""
    chunk = int(ctx.sizes["chunk"])
    out = {"ddf_fp32": DDFDepth(rep, "fp32", chunk=chunk), "ddf_bf16": DDFDepth(rep, "bf16", chunk=chunk)}
    compiling = compile_too and ctx.sizes.get("compile")
    if compiling:
        out["ddf_bf16_compiled"] = DDFDepth(rep, "bf16", compiled=True, chunk=chunk)
    if ctx.device.startswith("cuda") and importlib.util.find_spec("triton") is not None:
        for name, fused in [("ddf_bf16_fused", "mlp")] * bool(compiling) + [("ddf_bf16_fused_depth", "depth")]:
            try:
                start = clock()
                variant = DDFDepth(rep, "bf16", compiled=fused == "mlp", chunk=chunk, fused=fused)
                check_against(variant, out["ddf_bf16"], ctx.device)
                out[name] = variant
                if details is not None:
                    details.setdefault("cold", {})[f"{name}_build_and_check_s"] = clock() - start
            except Exception as err:  # the race goes on without it; the JSON says why
                if details is not None:
                    details[name] = f"not run: {one_line(err)}"
    return out


def check_against(depth: DDFDepth, reference: DDFDepth, device: str, n: int = 4096) -> None:
    """Raise unless depth answers n incoherent rays like reference (hit masks agree on 98 %, depth MAE < 1e-2);
    the copy to the host synchronizes, so a kernel's fault is raised here. (A CUDA fault sticks to the
    process: the race then fails as a whole, with that error.)"""
    o, d = (torch.as_tensor(a, device=device) for a in incoherent_rays(n, seed=5))
    diff = answer_diff(depth(o, d).cpu().numpy(), reference(o, d).cpu().numpy())
    if diff["mask_disagreement"] > 0.02 or not diff["depth_mae"] < 1e-2:
        raise ValueError(f"answers differ from the bf16 forward's: hit masks disagree on {diff['mask_disagreement']:.3f}, "
                         f"depth MAE {diff['depth_mae']:.2e}")


def embree_all_cores(ctx: Context, oracle, mesh, result: SectionResult) -> tuple[dict[str, Callable], EmbreePool | None]:
    """({"embree_all_cores": contestant}, the pool to close or None): open3d's Embree through the oracle, or
    where the oracle is Warp's (a machine without open3d) embreex in one process per core; ({}, None) with
    the reason in result.details where neither is installed."""
    if not ctx.sizes.get("embree", True):
        result.details["embree_all_cores"] = "not run: embree=false (the depth reference is the oracle's)"
        return {}, None
    if ctx.oracle_backend == "open3d":
        result.details["embree_all_cores"] = "open3d RaycastingScene (Embree on every core)"
        return {"embree_all_cores": lambda o, d, on, dn: oracle.hit_distance(on, dn)}, None
    if importlib.util.find_spec("embreex") is None:
        result.details["embree_all_cores"] = "not run: neither open3d (the oracle is Warp's) nor embreex is installed"
        return {}, None
    pool = EmbreePool(mesh)
    result.details["embree_all_cores"] = f"embreex in {pool.workers} processes (ddfbench.truth.embree_pool; no open3d)"
    return {"embree_all_cores": lambda o, d, on, dn: pool.hit_distance(on, dn)}, pool


def sdf_depth(rep, o: np.ndarray, d: np.ndarray) -> np.ndarray:
    return rep.intersect(o, d, normals=False).t


def answer_diff(t: np.ndarray, t_fp32: np.ndarray) -> dict[str, float]:
    """A DDF variant's depth t (N,) against another's (its fp32 answer; in check_against the bf16 one): MAE where
    both hit, and the share of rays whose hit masks disagree."""
    a, b = np.isfinite(t), np.isfinite(t_fp32)
    both = a & b
    return {"depth_mae": float(np.abs(t[both] - t_fp32[both]).mean()) if both.any() else 0.0,
            "mask_disagreement": float((a != b).mean())}
