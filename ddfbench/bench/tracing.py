"""Section 4, sphere tracing: field evaluations per pixel and time of ddfbench's tracer against the
naive all-rays loop (naive_trace below: every ray every step, the field evaluated
twice per step, for max_steps steps), for a neural SDF and a grid SDF of the shape.

The neural SDF is the conf/model/neural_sdf.yaml preset trained here for `fit_seconds` on oracle SDF
samples (ddfbench.sampling.oracle_sdf); the grid SDF is a level-set grid at `grid_resolution`.
Both render one pinhole view (ddfbench.bench.views.view_rays) of `px`^2 rays. The naive loop is run once
(it is long and has no lazy setup: the tracer's runs before it warm everything), the tracer
1 + warmup + repeats times. Agreement of the hit masks with the oracle is in the details.
Sizes: shape, neural_px, grid_px, fit_seconds, n_samples, grid_resolution, neural (model overrides).
"""

from __future__ import annotations

import numpy as np
import torch

from ddfbench.bench.context import Context, model_preset
from ddfbench.bench.results import SectionResult, Target, compare
from ddfbench.bench.timing import measure, once, precisions
from ddfbench.bench.views import view_rays
from ddfbench.core.geometry import box_entry
from ddfbench.core.representation import Budget, FitData
from ddfbench.evaluate.trace import TorchField, sphere_trace
from ddfbench.models.grid_sdf import GridSDF
from ddfbench.models.neural_sdf import NeuralSDF
from ddfbench.sampling.oracle_sdf import oracle_sdf_samples

TARGET = Target(">=", 3.0)


def naive_trace(field: TorchField, origins: np.ndarray, directions: np.ndarray, domain: float,
                eps: float = 1e-5, eps_abs: float = 1e-6, max_steps: int = 256) -> tuple[np.ndarray, int]:
    """The baseline loop: every ray every step, field evaluated twice per step. Returns (t (inf unless hit), evals)."""
    o, d = torch.from_numpy(origins), torch.from_numpy(directions)
    t_enter, t_exit, _ = box_entry(o, d, domain)
    t = t_enter.clone()
    evals = 0
    with torch.no_grad():
        for _ in range(max_steps):
            t = t + field(o + t[:, None] * d)
            f = field(o + t[:, None] * d)
            evals += 2 * len(t)
        hit = (f.abs() < eps * t + eps_abs) & (t_enter <= t_exit) & (t <= t_exit)
    return torch.where(hit, t, torch.full_like(t, float("inf"))).numpy(), evals


def neural_sdf(ctx: Context, preset: str = "neural_sdf") -> tuple[NeuralSDF, dict]:
    """conf/model/<preset>.yaml (sizes' `neural` overrides) fit `fit_seconds` on oracle SDF samples."""
    s = ctx.sizes
    shape, oracle = ctx.shape(s["shape"]), ctx.oracle(s["shape"])
    rep = NeuralSDF(model_preset(preset, **dict(s.get("neural") or {})))
    return rep, ctx.timed_fit(rep, oracle_sdf_samples(shape.mesh, oracle, int(s["n_samples"]), seed=0))


def grid_sdf(ctx: Context) -> tuple[GridSDF, dict]:
    s = ctx.sizes
    shape, oracle = ctx.shape(s["shape"]), ctx.oracle(s["shape"])
    rep = GridSDF(model_preset("grid_sdf", resolution=int(s["grid_resolution"]), build="levelset"))
    rep.device = ctx.device
    stats = rep.fit(FitData(None, shape.mesh, oracle), Budget(device=ctx.device, n_probes=0))
    return rep, {"resolution": rep.resolution, "build_seconds": stats.seconds}


def _on_device(field, device: str):
    """naive_trace hands CPU tensors: move them to the field's device and the answer back."""
    if device == "cpu":
        return field
    return lambda p: field(p.to(device)).cpu()


def run(ctx: Context) -> SectionResult:
    s = ctx.sizes
    oracle = ctx.oracle(s["shape"])
    result = SectionResult()
    for name, build, px, precs in (("neural_sdf", neural_sdf, s["neural_px"], precisions(ctx.device)),
                                   ("grid_sdf", grid_sdf, s["grid_px"], ["fp32"])):
        rep, info = build(ctx)
        o, d = view_rays(int(px))
        n = len(o)
        gt_hit = np.isfinite(oracle.hit_distance(o, d))
        for prec in (p for p in precs if p != "bf16"):  # the hit tolerance (1e-5) is below bf16's resolution
            kw = dict(device=ctx.device, precision=prec)
            traced, tracer_t = measure(lambda: sphere_trace(rep.field, o, d, rep.domain, rep.trace_options, ctx.device),
                                       ctx.repeats, ctx.warmup, **kw)
            (naive_t_values, naive_evals), naive_t = once(
                lambda: naive_trace(_on_device(rep.field, ctx.device), o, d, rep.domain, rep.trace_options.eps,
                                    rep.trace_options.eps_abs, rep.trace_options.max_steps), **kw)
            naive_hit = np.isfinite(naive_t_values)
            result.details[f"{name}_{prec}"] = {
                **info, "rays": n, "tracer": tracer_t.as_dict(), "naive": naive_t.as_dict(),
                "tracer_evals": traced.field_evals, "naive_evals": naive_evals,
                "tracer_host_syncs": traced.host_syncs,
                "tracer_hit_share": float(traced.hit.mean()), "undecided": int((traced.status == 2).sum()),
                "mask_agreement_tracer_vs_oracle": float((traced.hit == gt_hit).mean()),
                "mask_agreement_naive_vs_oracle": float((naive_hit == gt_hit).mean()),
                "mask_agreement_tracer_vs_naive": float((traced.hit == naive_hit).mean()),
            }
            result.rows.append(compare(
                "tracing", f"{name}: field evaluations per pixel, ddfbench tracer", traced.field_evals / n, "evals/px",
                "naive all-rays loop (2 evals per step, max_steps)", naive_evals / n, inverse=True, target=TARGET,
                note="ratio = how many times fewer evaluations", threads=ctx.threads, **kw))
            result.rows.append(compare(
                "tracing", f"{name}: seconds per frame, ddfbench tracer", tracer_t.median_s, "s",
                "naive all-rays loop seconds", naive_t.median_s, inverse=True,
                note="ratio = speedup" + ("" if ctx.device == "cpu" else
                                          "; the naive loop also copies points to the device and back each step"),
                threads=ctx.threads, **kw))
    return result
