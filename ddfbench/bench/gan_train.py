"""Section 11, GAN training pass: the thesis generator and discriminator's forward and backward with the max
pools as the family trains them (ddfbench.models._stride1_pool) against torch's nn.MaxPool1d, side by side.

One pass, the network work of a thesis step without its optimizers and near-surface term: P = G(x) on `batch`
random points; D on the real (x, L) and the detached fake (x, P) with the least-squares discriminator loss,
backward; then the generator's MSE plus adversarial term through D on (x, P), backward. The two network pairs
hold the same weights, so both ways compute the same gradients (tests/test_stride1_pool.py) and the ratio is
the speed-up the pools give the pass. Passes/s x batch = samples/s. Sizes: batch.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from ddfbench.bench.context import DOMAIN, Context
from ddfbench.bench.results import SectionResult, compare
from ddfbench.bench.timing import measure_side_by_side
from ddfbench.models.gan_sdf import adversarial_losses, discriminator, generator


def training_pass(batch: int, torch_pools: bool, device: str):
    """(a () -> None pass of G and D on a fixed batch, (G, D) with seed 0 weights); torch_pools: nn.MaxPool1d
    in both networks. Each pass adds its gradients to the networks' .grad."""
    torch.manual_seed(0)
    g, d = generator().to(device), discriminator(False).to(device)
    if torch_pools:
        for net in (g, d):
            net.pool = torch.nn.MaxPool1d(3, stride=1)
    gen = torch.Generator().manual_seed(1)
    x = ((torch.rand(batch, 3, generator=gen) * 2 - 1) * DOMAIN).to(device)
    target = (torch.randn(batch, generator=gen) * 0.1).to(device)
    g_adv, d_adv = adversarial_losses("least_squares")

    def run() -> None:
        pred = g(x)
        d_adv(d(torch.cat([x, target[:, None]], 1)), d(torch.cat([x, pred.detach()[:, None]], 1))).backward()
        (F.mse_loss(pred, target) + 5.0 * g_adv(d(torch.cat([x, pred[:, None]], 1)))).backward()

    return run, (g, d)


def run(ctx: Context) -> SectionResult:
    batch, result = int(ctx.sizes["batch"]), SectionResult()
    fns = {way: training_pass(batch, way == "torch", ctx.device)[0] for way in ("stride1", "torch")}
    timed = measure_side_by_side(fns, ctx.repeats, ctx.warmup, ctx.device)
    rate = {way: t.rate(batch) for way, (_, t) in timed.items()}
    result.details = {"batch": batch, "timings": {way: t.as_dict() for way, (_, t) in timed.items()}}
    result.rows.append(compare(
        "gan_train", f"gan_sdf G+D forward and backward, batch {batch}, pools as Stride1MaxPool1d: samples/s",
        rate["stride1"], "samples/s", "the same pass with torch's nn.MaxPool1d, samples/s", rate["torch"],
        device=ctx.device, threads=ctx.threads))
    return result
