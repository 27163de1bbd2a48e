"""Section 10, field cost: what one point of a network SDF costs to evaluate, and how close to the device's
matrix-product speed each network gets, measured side by side in one process.

Figures (no grad, random points in the field box, networks, points and matrices on the bench's device,
`threads` torch threads):
- the GAN-SDF generator (the thesis' Conv1d stack) on `points` points at each eval chunk in `chunks`
  (points per call), two ways: as the family evaluates it (matrix products, ddfbench.models._gan_gemm)
  against the Conv1d module it trains (the ratio is the rewrite's speed-up), each at its fastest chunk
  against the tuned neural SDF's field on one call of 65,536 points (the SDF families' batch);
- each network's achieved GFLOP/s (multiply-adds of its Linear and Conv1d layers x 2 per point, from
  `flops_per_point`) against a dense fp32 matrix product of side `gemm` on the same threads, the speed a
  well-shaped product reaches here.
A sphere-traced frame costs (field evaluations) x (time a point), so the two rates and a render's
evaluation counts (record `counts.field_evals`) bound the render-time ratio of the two families.
Sizes: points, chunks, gemm, sdf_preset, gan_preset.
"""

from __future__ import annotations

import torch
from torch import nn

from ddfbench.bench.context import DOMAIN, Context, model_preset
from ddfbench.bench.results import SectionResult, compare
from ddfbench.bench.timing import measure_side_by_side
from ddfbench.models import load_family
from ddfbench.models._sdf_family import FIELD_BATCH as SDF_BATCH  # points a call of the SDF families' field


def flops_per_point(net: nn.Module, in_dim: int = 3) -> int:
    """2 x the multiply-adds of every Linear and Conv1d layer for one input point (activations, pooling
    and encodings not counted), read from the layer shapes during one forward pass."""
    macs = [0]

    def count(module: nn.Module, _inputs, output: torch.Tensor) -> None:
        if isinstance(module, nn.Linear):
            macs[0] += module.in_features * module.out_features * (output.numel() // output.shape[-1])
        elif isinstance(module, nn.Conv1d):  # output (1, out_channels, L_out)
            macs[0] += output.numel() * module.in_channels // module.groups * module.kernel_size[0]

    hooks = [m.register_forward_hook(count) for m in net.modules() if isinstance(m, (nn.Linear, nn.Conv1d))]
    try:
        with torch.no_grad():
            net(torch.zeros(1, in_dim, device=next(net.parameters()).device))
    finally:
        for h in hooks:
            h.remove()
    return 2 * macs[0]


def run(ctx: Context) -> SectionResult:
    s, result = ctx.sizes, SectionResult()
    n, side = int(s["points"]), int(s["gemm"])
    dev = ctx.device
    sdf = load_family("neural_sdf")(model_preset(s["sdf_preset"])).to(dev)
    gan = load_family("gan_sdf")(model_preset(s["gan_preset"])).to(dev)
    gen = torch.Generator().manual_seed(0)
    points = ((torch.rand(n, 3, generator=gen) * 2 - 1) * DOMAIN).to(dev)
    sdf_points = ((torch.rand(SDF_BATCH, 3, generator=gen) * 2 - 1) * DOMAIN).to(dev)
    a, b = torch.rand(side, side, generator=gen).to(dev), torch.rand(side, side, generator=gen).to(dev)

    def gan_at(chunk: int):
        def fn():
            gan.eval_batch = chunk
            return gan.field(points)
        return fn

    def conv1d_at(chunk: int):
        return lambda: torch.cat([gan.net(points[i : i + chunk]) for i in range(0, n, chunk)])

    chunks = [int(c) for c in s["chunks"]]
    fns = {"sdf": lambda: sdf.field(sdf_points), "gemm": lambda: a @ b,
           **{f"gan@{c}": gan_at(c) for c in chunks}, **{f"conv1d@{c}": conv1d_at(c) for c in chunks}}
    with torch.no_grad():
        timed = measure_side_by_side(fns, ctx.repeats, ctx.warmup, ctx.device)
    flops = {"sdf": flops_per_point(sdf.net), "gan": flops_per_point(gan.net)}
    gemm_gflops = 2 * side**3 / timed["gemm"][1].median_s / 1e9
    rate = {name: t.rate(SDF_BATCH if name == "sdf" else n) for name, (_, t) in timed.items() if name != "gemm"}
    kw = dict(device=ctx.device, threads=ctx.threads)
    result.details = {"flops_per_point": flops, "points": n, "gemm_side": side, "gemm_gflops": gemm_gflops,
                      "timings": {name: t.as_dict() for name, (_, t) in timed.items()}}
    for c in chunks:
        result.rows.append(compare(
            "field_cost", f"gan_sdf generator as matrix products, {c} points a call: points/s", rate[f"gan@{c}"],
            "points/s", f"the same generator through its Conv1d module, {c} points a call", rate[f"conv1d@{c}"], **kw))
    best = {way: max(chunks, key=lambda c: rate[f"{way}@{c}"]) for way in ("gan", "conv1d")}
    sdf_label = f"{s['sdf_preset']} field, {SDF_BATCH} points a call, points/s"
    for way, label in (("gan", "gan_sdf field (matrix products)"), ("conv1d", "gan_sdf Conv1d module")):
        result.rows.append(compare(
            "field_cost", f"{label}, {best[way]} points a call (its fastest): points/s", rate[f"{way}@{best[way]}"],
            "points/s", sdf_label, rate["sdf"], **kw))
    for name, label, r in (("sdf", f"{s['sdf_preset']} field ({SDF_BATCH} a call)", rate["sdf"]),
                           ("gan", f"gan_sdf field ({best['gan']} a call, its fastest)", rate[f"gan@{best['gan']}"])):
        result.rows.append(compare(
            "field_cost", f"{label}: GFLOP/s ({flops[name]:,} FLOP a point)", r * flops[name] / 1e9, "GFLOP/s",
            f"dense fp32 matrix product {side}x{side}, GFLOP/s", gemm_gflops, **kw))
    return result
