"""A stride-1 max pool whose backward pass is cheap on CPU, with torch's values and gradients bit for bit.

torch's MaxPool1d, when its input needs a gradient, writes an int64 index per output (2x the output's
bytes, fresh pages every call) and on one CPU thread took 80 ms (16 x 250 channels) and 150 ms (32 x 244)
forward and backward at the GAN's batch of 1024 points, over half of a thesis training step. This pool runs
torch's plain forward (no indices), keeps its input and output, and in the backward pass finds each window's
first maximum again by comparison: the tap i that holds it takes the window's gradient, as in torch's
kernel, which also gives ties to the first maximum. The gradient an input element gets from its up-to-
`window` windows is summed in torch's order (window by window, left to right), so the sums round alike.

A window holding a NaN: torch passes its gradient to the NaN; here it goes to the window's last tap
(training stops on a non-finite loss first; ddfbench.train's NaN guard).
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
        taken = None   # (N, C, n) bool: the window's maximum found at an earlier tap
        per_tap = []   # gradient of taps 0 .. k-2, each (N, C, n)
        for i in range(k - 1):
            at_i = torch.eq(h[..., i : i + n], y)
            if taken is not None:
                at_i.logical_and_(taken.logical_not())
                taken.logical_or_(at_i)
            else:
                taken = at_i.clone()
            per_tap.append(grad_out * at_i)
        grad_in = torch.empty_like(h)
        grad_in[..., : k - 1] = 0
        last = grad_in[..., k - 1 :].copy_(grad_out)
        for g in per_tap:  # exactly one tap holds the window's gradient: go - go = 0 and go - 0 = go exactly
            last.sub_(g)
        for i in range(k - 2, -1, -1):  # element j sums windows j-k+1 .. j in that order, as torch's kernel
            grad_in[..., i : i + n] += per_tap[i]
        return grad_in, None


class Stride1MaxPool1d(nn.MaxPool1d):
    """nn.MaxPool1d(window, stride=1) (no padding), the same values and gradients; faster backward on CPU."""

    def __init__(self, window: int):
        super().__init__(window, stride=1)

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        if torch.is_grad_enabled() and h.requires_grad:
            return _FirstMaxGrad.apply(h, int(self.kernel_size))
        return F.max_pool1d(h, self.kernel_size, 1)
