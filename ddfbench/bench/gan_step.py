"""Seconds a thesis GAN training step takes: G and D (ddfbench.models.gan_sdf), batch 1024 of random points,
the D update, then the G loss (MSE + near-surface + adversarial) and its update, Adam on both.

usage: python -m ddfbench.bench.gan_step THREADS STEPS {stride1|torch} {heap|default}
  stride1: the family's pools (ddfbench.models._stride1_pool); torch: nn.MaxPool1d in both networks
  heap: ddfbench.core.heap.keep_freed_blocks() first (as a run does); default: glibc's own settings
Prints: pools, heap, threads, seconds a step (mean of STEPS after 3 warm steps). Run one process per cell
(reports/bench/gan_train): the heap setting holds for the process.
"""

from __future__ import annotations

import argparse
import time
from typing import Callable

import torch
import torch.nn.functional as F

from ddfbench.core import heap
from ddfbench.models.gan_sdf import adversarial_losses, discriminator, generator, near_surface_term

POOLS = ("stride1", "torch")
HEAPS = ("heap", "default")
WARM_STEPS = 3
BATCH = 1024


def gan_step(pools: str, n_points: int = 250_000) -> Callable[[], None]:
    """One thesis training step (D update, then G update) on a fixed random cloud of n_points labelled points;
    pools='torch' swaps both networks' pools for nn.MaxPool1d."""
    torch.manual_seed(0)
    g, d = generator(), discriminator(False)
    if pools == "torch":
        for net in (g, d):
            net.pool = torch.nn.MaxPool1d(3, stride=1)
    opt_g, opt_d = (torch.optim.Adam(n.parameters(), 1e-4, betas=(0.5, 0.999)) for n in (g, d))
    x, s = torch.rand(n_points, 3) - 0.5, torch.randn(n_points) * 0.4
    g_adv, d_adv = adversarial_losses("least_squares")

    def step() -> None:
        idx = torch.randint(0, len(x), (BATCH,))
        xb, sb = x[idx], s[idx]
        pred = g(xb)
        opt_d.zero_grad(set_to_none=True)
        d_adv(d(torch.cat([xb, sb[:, None]], 1)), d(torch.cat([xb, pred.detach()[:, None]], 1))).backward()
        opt_d.step()
        loss = (F.mse_loss(pred, sb) + 2.0 * near_surface_term(pred, sb, "exp")
                + 5.0 * g_adv(d(torch.cat([xb, pred[:, None]], 1))))
        opt_g.zero_grad(set_to_none=True)
        loss.backward()
        opt_g.step()

    return step


def step_seconds(step: Callable[[], None], steps: int) -> float:
    """Mean seconds of `steps` calls of step after WARM_STEPS untimed ones."""
    for _ in range(WARM_STEPS):
        step()
    start = time.perf_counter()
    for _ in range(steps):
        step()
    return (time.perf_counter() - start) / steps


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m ddfbench.bench.gan_step", description=__doc__.split("\n")[0])
    parser.add_argument("threads", type=int)
    parser.add_argument("steps", type=int)
    parser.add_argument("pools", choices=POOLS)
    parser.add_argument("heap", choices=HEAPS)
    args = parser.parse_args(argv)
    if args.heap == "heap" and not heap.keep_freed_blocks():
        parser.error("heap: glibc's mallopt is not available here")
    torch.set_num_threads(args.threads)
    print(args.pools, args.heap, args.threads, f"{step_seconds(gan_step(args.pools), args.steps):.3f}")


if __name__ == "__main__":
    main()
