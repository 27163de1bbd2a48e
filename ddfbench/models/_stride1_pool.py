"""A stride-1 max pool whose backward pass is cheap on CPU, with torch's values and gradients bit for bit.

torch's MaxPool1d, when its input needs a gradient, writes an int64 index per output (2x the output's
bytes); in a profile of the thesis GAN's training step (batch 1024, one CPU thread) its forward took 54 % of
the step and its backward another 8 % (reports/bench/gan_train/README.md). This pool runs
torch's plain forward (no indices), keeps its input and output, and in the backward pass finds each window's
first maximum again by comparison: the tap i that holds it takes the window's gradient, as in torch's
kernel, which also gives ties to the first maximum. The gradient an input element gets from its up-to-
`window` windows is summed in torch's order (window by window, left to right), so the sums round alike.

Under create_graph the backward is written as masks times the incoming gradient, so a double backward
(the GAN's R1 penalty, model.w_gp) matches torch's too; otherwise the last tap's share is the incoming
gradient less the other taps' (exact, fewer passes). Where they differ: a window holding a NaN (torch
passes its gradient to the NaN, here the window's last tap takes it) and an infinite incoming gradient
(inf x 0 makes NaN beside it); training stops on either first (ddfbench.fit.train's NaN guard). An in-place
operation on the pool's output raises, as the output is kept for the backward. Off CPU (not measured there)
and without autograd the pool is torch's own.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


class _FirstMaxGrad(torch.autograd.Function):
    """(N, C, L) -> (N, C, L - window + 1); backward: each window's gradient to its first maximal tap."""

    @staticmethod
    def forward(ctx, h: torch.Tensor, window: int) -> torch.Tensor:
        y = F.max_pool1d(h, window, 1)
        ctx.save_for_backward(h, y)
        ctx.window = window
        return y

    @staticmethod
    def backward(ctx, grad_out: torch.Tensor):
        h, y = ctx.saved_tensors
        k, n = ctx.window, y.shape[-1]
        free = torch.ones_like(y, dtype=torch.bool)  # (N, C, n): no earlier tap holds the window's maximum
        per_tap = []  # (N, C, n) each: the window gradients that taps 0 .. k-2 take
        for i in range(k - 1):
            at_i = torch.eq(h[..., i : i + n], y).logical_and_(free)
            free.logical_and_(at_i.logical_not())
            per_tap.append(grad_out * at_i)
        grad_in = torch.empty_like(h)
        grad_in[..., : k - 1] = 0
        if torch.is_grad_enabled():  # create_graph: a double backward differentiates this, so masks only
            grad_in[..., k - 1 :] = grad_out * free
        else:  # one tap holds each window's gradient: go - go = 0 and go - 0 = go exactly, and cheaper
            last = grad_in[..., k - 1 :].copy_(grad_out)
            for g in per_tap:
                last.sub_(g)
        for i in range(k - 2, -1, -1):  # element j sums windows j-k+1 .. j in that order, as torch's kernel
            grad_in[..., i : i + n] += per_tap[i]
        return grad_in, None


class Stride1MaxPool1d(nn.MaxPool1d):
    """nn.MaxPool1d(window, stride=1) (no padding), (N, C, L) -> (N, C, L - window + 1): the same values and
    gradients, a faster backward on CPU."""

    def __init__(self, window: int):
        super().__init__(window, stride=1)

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        if torch.is_grad_enabled() and h.requires_grad and h.device.type == "cpu":
            return _FirstMaxGrad.apply(h, int(self.kernel_size))
        return F.max_pool1d(h, self.kernel_size, 1)
