"""Seconds a thesis GAN training step takes: G and D (ddfbench.models.gan_sdf), batch 1024 of random points,
the D update, then the G loss (MSE + near-surface + adversarial) and its update, Adam on both.
usage: python step_time.py THREADS STEPS {stride1|torch} {heap|default}
  stride1: the family's pools (ddfbench.models._stride1_pool); torch: nn.MaxPool1d in both networks
  heap: ddfbench.heap.keep_freed_blocks() first (as a run does); default: glibc's own settings
Prints: pools, heap, threads, seconds a step (mean of STEPS after 3 warm steps)."""

import sys
import time

import torch
import torch.nn.functional as F

from ddfbench import heap
from ddfbench.models.gan_sdf import adversarial_losses, discriminator, generator, near_surface_term

threads, steps, pools, mode = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4]
if mode == "heap":
    assert heap.keep_freed_blocks()
torch.set_num_threads(threads)
torch.manual_seed(0)
g, d = generator(), discriminator(False)
if pools == "torch":
    for net in (g, d):
        net.pool = torch.nn.MaxPool1d(3, stride=1)
opt_g, opt_d = (torch.optim.Adam(n.parameters(), 1e-4, betas=(0.5, 0.999)) for n in (g, d))
x, s = torch.rand(250_000, 3) - 0.5, torch.randn(250_000) * 0.4
g_adv, d_adv = adversarial_losses("least_squares")


def step() -> None:
    idx = torch.randint(0, len(x), (1024,))
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


for _ in range(3):
    step()
start = time.perf_counter()
for _ in range(steps):
    step()
print(pools, mode, threads, f"{(time.perf_counter() - start) / steps:.3f}")
