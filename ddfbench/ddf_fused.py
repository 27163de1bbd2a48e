"""The DDF's MLP as one Triton kernel: every layer of a block of rays computed in registers.

The layer-by-layer forward (eager or torch.compile) writes each layer's activations to GPU memory and
reads them back, ~N * width * 2 bytes a layer in bf16: for a 128-wide MLP that traffic, not the
~10^5 FLOP a ray, bounds it (measured on an H100: reports/bench/bench-cuda-*.md). Here a program takes
BLOCK rays, reads their encoded inputs (BLOCK, K0) bf16 once, runs every Linear + ReLU as a bf16 matrix
product with fp32 accumulation (bias added in fp32, where autocast adds a bf16 bias; then rounded to bf16) and
writes only the output head (BLOCK, n_out) in fp32 (a row sum each: n_out <= 2). Weights (~33 KB a 128x128 layer) stay in L2.

Supports the DDF networks of ddfbench.models.ddf.network.DDFNet with ReLU (weight norm included: its
Linear's weight is the computed one; dropout is the identity at inference), no line grid, equal widths a
power of two from 64 to 256 (`supported` says why not otherwise). Runs wherever
Triton runs its kernels: CUDA, or the CPU under TRITON_INTERPRET=1 (how the tests check it without a GPU).
"""

from __future__ import annotations

import contextlib
import os

import torch
import triton
import triton.language as tl
from torch import nn

from ddfbench.models.ddf.network import DDFNet

# Triton 3.6-3.7 on sm_90 reads shared memory out of bounds (an illegal memory access, or silent corruption) in
# kernels with two or more tl.dot where a dot dimension is 16 or 32 (seen here on an H100 with a 16-wide output
# dot; triton-lang/triton#10486, #11366): every dot dimension here is 64 or more, the head is a reduction
MIN_DOT = 64
# Triton's CPU interpreter multiplies bf16 matrices wrongly (its numpy has no bf16): there the bf16 values are
# multiplied as float32, which is exact for bf16 products, and summed in float32 as the tensor cores do
INTERPRETED = os.environ.get("TRITON_INTERPRET") == "1"


@triton.jit
def _mm(a, b, DOT_F32: tl.constexpr):
    """a (M, K) @ b (K, N), bf16 in, float32 out."""
    if DOT_F32:
        c = tl.dot(a.to(tl.float32), b.to(tl.float32), input_precision="ieee")
    else:
        c = tl.dot(a, b)
    return c


@triton.jit
def _mlp_kernel(x_ptr, w0_ptr, b0_ptr, wh_ptr, bh_ptr, wo_ptr, bo_ptr, y_ptr, n_rows,
                K0: tl.constexpr, WIDTH: tl.constexpr, HIDDEN: tl.constexpr, N_OUT: tl.constexpr,
                BLOCK: tl.constexpr, DOT_F32: tl.constexpr):
    """y (n_rows, N_OUT) fp32 = out(relu(... relu(x W0 + b0) ...)) for x (n_rows, K0) bf16; W0 (K0, WIDTH),
    hidden Wh (HIDDEN, WIDTH, WIDTH) bf16, stored input-major; out Wo (N_OUT, WIDTH) bf16; biases fp32."""
    rows = tl.program_id(0).to(tl.int64) * BLOCK + tl.arange(0, BLOCK)  # int64: n_rows * K0 may pass 2^31
    live = rows < n_rows
    k = tl.arange(0, K0)
    c = tl.arange(0, WIDTH)
    x = tl.load(x_ptr + rows[:, None] * K0 + k[None, :], mask=live[:, None], other=0.0)
    h = _mm(x, tl.load(w0_ptr + k[:, None] * WIDTH + c[None, :]), DOT_F32) + tl.load(b0_ptr + c)[None, :]
    h = tl.maximum(h, 0.0).to(tl.bfloat16)
    for i in tl.static_range(HIDDEN):
        w = tl.load(wh_ptr + i * WIDTH * WIDTH + c[:, None] * WIDTH + c[None, :])
        h = _mm(h, w, DOT_F32) + tl.load(bh_ptr + i * WIDTH + c)[None, :]
        h = tl.maximum(h, 0.0).to(tl.bfloat16)
    h32 = h.to(tl.float32)
    for j in tl.static_range(N_OUT):  # the head: N_OUT <= 2 outputs, each a row sum
        w = tl.load(wo_ptr + j * WIDTH + c).to(tl.float32)
        tl.store(y_ptr + rows * N_OUT + j, tl.sum(h32 * w[None, :], axis=1) + tl.load(bo_ptr + j), mask=live)


def supported(net: DDFNet) -> str | None:
    """None if net's MLP can run fused, else why not (one line)."""
    if net.grid is not None:
        return "the line grid's features are not fused"
    if any(not isinstance(m, (nn.Linear, nn.ReLU, nn.Dropout)) for m in net.body):
        return "only Linear + ReLU bodies are fused (not softplus)"
    widths = {m.out_features for m in _linears(net)}
    width = max(widths)
    if width & (width - 1) or not MIN_DOT <= width <= 256 or len(widths) > 1:
        return f"width {width}: the fused MLP needs equal widths, a power of two from {MIN_DOT} to 256"
    return None


def _linears(net: DDFNet) -> list[nn.Linear]:
    return [m for m in net.body if isinstance(m, nn.Linear)]


def _pow2(n: int) -> int:
    return max(MIN_DOT, 1 << (int(n) - 1).bit_length())


class FusedMLP:
    """net's body + output head as one kernel: (N, n_in) float features -> (N, n_out) float32.

    The weights are copied once (bf16, transposed, zero-padded), so a later change to net is not seen."""

    def __init__(self, net: DDFNet):
        why = supported(net)
        if why:
            raise ValueError(f"FusedMLP: {why}")
        linears = _linears(net)
        first, hidden, out = linears[0], linears[1:], net.out
        dev = first.weight.device
        self.n_in, self.width, self.n_out = first.in_features, first.out_features, out.out_features
        self.k0 = _pow2(self.n_in)
        bf16 = dict(device=dev, dtype=torch.bfloat16)
        with torch.no_grad():
            self.w0 = torch.zeros(self.k0, self.width, **bf16)
            self.w0[: self.n_in] = first.weight.t()
            self.b0 = first.bias.detach().float().clone()
            self.wh = (torch.stack([m.weight.t() for m in hidden]) if hidden else torch.zeros(1, self.width, self.width))
            self.wh = self.wh.to(**bf16).contiguous()
            self.bh = (torch.stack([m.bias for m in hidden]) if hidden else torch.zeros(1, self.width)).float().to(dev)
            self.wo = out.weight.to(**bf16).contiguous()
            self.bo = out.bias.detach().float().clone()
        self.hidden = len(hidden)
        self.block = 128 if self.width <= 128 else 64
        self.warps = 8 if self.width >= 128 else 4

    def pad(self, feats: torch.Tensor) -> torch.Tensor:
        """features (N, n_in) -> the kernel's input (N, K0) bf16 (zero columns beyond n_in)."""
        return nn.functional.pad(feats, (0, self.k0 - self.n_in)).to(torch.bfloat16).contiguous()

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        """x: pad()'s output (N, K0) bf16 -> (N, n_out) float32."""
        if x.device != self.w0.device:
            raise ValueError(f"FusedMLP: input on {x.device}, weights on {self.w0.device}")
        n = len(x)
        y = torch.empty(n, self.n_out, device=x.device, dtype=torch.float32)
        if n:
            # Triton launches on the current CUDA device and its stream: make that x's
            with torch.cuda.device(x.device) if x.is_cuda else contextlib.nullcontext():
                _mlp_kernel[(triton.cdiv(n, self.block),)](
                    x, self.w0, self.b0, self.wh, self.bh, self.wo, self.bo, y, n, K0=self.k0, WIDTH=self.width,
                    HIDDEN=self.hidden, N_OUT=self.n_out, BLOCK=self.block, DOT_F32=INTERPRETED,
                    num_warps=self.warps)
        return y
