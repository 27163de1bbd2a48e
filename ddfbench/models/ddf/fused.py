"""The DDF as Triton kernels: every layer of a block of rays computed in registers.

The layer-by-layer forward (eager or torch.compile) writes each layer's activations to GPU memory and
reads them back, ~N * width * 2 bytes a layer in bf16: for a 128-wide MLP that traffic, not the
~10^5 FLOP a ray, bounds it (measured on an H100: reports/bench/bench-cuda-*.md). Two kernels:
- FusedMLP: a program takes BLOCK rows of the encoded input (BLOCK, K0) bf16, runs every Linear + ReLU as a
  bf16 matrix product with fp32 accumulation (bias added in fp32, where autocast adds a bf16 bias; then rounded
  to bf16) and writes only the output head (BLOCK, n_out) in fp32 (a row sum each: n_out <= 2). Weights
  (~33 KB a 128x128 layer) stay in L2.
- FusedDepth: the whole answer of a ray in one kernel: it reads origins and directions (N, 3) fp32, computes the
  box entry, the ray parameterization and its Fourier encoding in registers, runs the same MLP and applies
  the hit rule, writing only t (N,) fp32: no (N, K0) input goes through memory and there is one launch.

Supports the DDF networks of ddfbench.models.ddf.network.DDFNet with ReLU (weight norm included: its
Linear's weight is the computed one; dropout is the identity at inference), no line grid, equal widths a
power of two from 64 to 256, and (FusedDepth) unit-vector directions (`supported` says why not otherwise).
Block size and warps are chosen by Triton's autotuner on the device, per network shape and for small (< 2^18)
and large inputs (`FusedMLP.config` names the choice). Runs wherever Triton runs its kernels: CUDA, or the
CPU under TRITON_INTERPRET=1 (how the tests check it without a GPU; one fixed block there).
"""

from __future__ import annotations

import contextlib
import math
import os

import torch
import triton
import triton.language as tl
from torch import nn
from triton.language.extra import libdevice

from ddfbench.models.ddf.network import DDFNet

# Triton 3.6-3.7 on sm_90 reads shared memory out of bounds (an illegal memory access, or silent corruption) in
# kernels with two or more tl.dot where a dot dimension is 16 or 32 (seen here on an H100 with a 16-wide output
# dot; triton-lang/triton#10486, #11366): every dot dimension here is 64 or more, the head is a reduction
MIN_DOT = 64
# Triton's CPU interpreter multiplies bf16 matrices wrongly (its numpy has no bf16): there the bf16 values are
# multiplied as float32, which is exact for bf16 products, and summed in float32 as the tensor cores do
INTERPRETED = os.environ.get("TRITON_INTERPRET") == "1"
SMALL = 1 << 18  # inputs of fewer rows are tuned apart (launch-bound: another block size may win)
# encoding columns: the channel as given, the sine of channel * scale + phase (a cosine is a sine a quarter
# turn on), or a zero pad column
IDENTITY, SINE, PAD = 0, 1, 2


def _configs() -> list[triton.Config]:
    """Block sizes and warps the autotuner tries (each a compile: a few seconds)."""
    return [triton.Config({"BLOCK": b}, num_warps=w) for b, w in ((64, 4), (64, 8), (128, 4), (128, 8), (256, 8))]


def _fits(configs, named_args, **kwargs) -> list[triton.Config]:
    """Configs whose (BLOCK, WIDTH) fp32 accumulator stays within 128 KB of registers."""
    width = kwargs.get("WIDTH") or named_args.get("WIDTH") or 256
    return [c for c in configs if c.kwargs["BLOCK"] * width <= 256 * 128]


def _tuned(kernel, key: list[str]):
    """kernel autotuned over block size and warps per key (network shape, input size class; not interpreted)."""
    if INTERPRETED:
        return kernel
    return triton.autotune(configs=_configs(), key=key,
                           prune_configs_by={"early_config_prune": _fits})(kernel)


@triton.jit
def _mm(a, b, INTERP: tl.constexpr):
    """a (M, K) @ b (K, N), bf16 in, float32 out (INTERP: under the interpreter, as float32 products)."""
    if INTERP:
        c = tl.dot(a.to(tl.float32), b.to(tl.float32), input_precision="ieee")
    else:
        c = tl.dot(a, b)
    return c


@triton.jit
def _body(x, w0_ptr, b0_ptr, wh_ptr, bh_ptr, K0: tl.constexpr, WIDTH: tl.constexpr, HIDDEN: tl.constexpr,
          INTERP: tl.constexpr):
    """Every Linear + ReLU of x (BLOCK, K0) bf16 -> (BLOCK, WIDTH) float32 (its values bf16); W0 (K0, WIDTH),
    hidden Wh (HIDDEN, WIDTH, WIDTH) bf16, stored input-major; biases fp32."""
    k = tl.arange(0, K0)
    c = tl.arange(0, WIDTH)
    h = _mm(x, tl.load(w0_ptr + k[:, None] * WIDTH + c[None, :]), INTERP) + tl.load(b0_ptr + c)[None, :]
    h = tl.maximum(h, 0.0).to(tl.bfloat16)
    for i in tl.static_range(HIDDEN):
        w = tl.load(wh_ptr + i * WIDTH * WIDTH + c[:, None] * WIDTH + c[None, :])
        h = _mm(h, w, INTERP) + tl.load(bh_ptr + i * WIDTH + c)[None, :]
        h = tl.maximum(h, 0.0).to(tl.bfloat16)
    return h.to(tl.float32)


@triton.jit
def _head(h, wo_ptr, bo_ptr, j: tl.constexpr, WIDTH: tl.constexpr):
    """Output j (BLOCK,) fp32 of the last hidden activations h (BLOCK, WIDTH) fp32: a row sum with Wo[j] bf16."""
    w = tl.load(wo_ptr + j * WIDTH + tl.arange(0, WIDTH)).to(tl.float32)
    return tl.sum(h * w[None, :], axis=1) + tl.load(bo_ptr + j)


@triton.jit
def _mlp_kernel(x_ptr, w0_ptr, b0_ptr, wh_ptr, bh_ptr, wo_ptr, bo_ptr, y_ptr, n_rows, large,
                K0: tl.constexpr, WIDTH: tl.constexpr, HIDDEN: tl.constexpr, N_OUT: tl.constexpr,
                BLOCK: tl.constexpr, INTERP: tl.constexpr):
    """y (n_rows, N_OUT) fp32 = out(relu(... relu(x W0 + b0) ...)) for x (n_rows, K0) bf16; Wo (N_OUT, WIDTH)
    bf16 (`large`: the autotuner's size class, unused here)."""
    rows = tl.program_id(0).to(tl.int64) * BLOCK + tl.arange(0, BLOCK)  # int64: n_rows * K0 may pass 2^31
    live = rows < n_rows
    k = tl.arange(0, K0)
    x = tl.load(x_ptr + rows[:, None] * K0 + k[None, :], mask=live[:, None], other=0.0)
    h = _body(x, w0_ptr, b0_ptr, wh_ptr, bh_ptr, K0, WIDTH, HIDDEN, INTERP)
    for j in tl.static_range(N_OUT):
        tl.store(y_ptr + rows * N_OUT + j, _head(h, wo_ptr, bo_ptr, j, WIDTH), mask=live)


@triton.jit
def _slab(o, d, half):
    """(enter, leave) (BLOCK,) of one axis of the closed box [-half, half] (geometry.ray_box's rule; on NVIDIA
    the division may round differently, moving t by an ulp or two)."""
    flat = d == 0.0
    inv = 1.0 / tl.where(flat, 1.0, d)
    t0 = (-half - o) * inv
    t1 = (half - o) * inv
    always = flat & (tl.abs(o) <= half)
    enter = tl.where(always, -float("inf"), tl.where(flat, float("inf"), tl.minimum(t0, t1)))
    leave = tl.where(always, float("inf"), tl.where(flat, -float("inf"), tl.maximum(t0, t1)))
    return enter, leave


@triton.jit
def _depth_kernel(o_ptr, d_ptr, chan_ptr, scale_ptr, phase_ptr, kind_ptr, w0_ptr, b0_ptr, wh_ptr, bh_ptr, wo_ptr,
                  bo_ptr, t_ptr, n_rows, large, half, min_hit, clamp_hit,
                  K0: tl.constexpr, WIDTH: tl.constexpr, HIDDEN: tl.constexpr, N_OUT: tl.constexpr,
                  RAY: tl.constexpr, BLOCK: tl.constexpr, INTERP: tl.constexpr):
    """t (n_rows,) fp32, the first hit of rays o + t d (o, unit d: (n_rows, 3) fp32), inf on a miss and for a ray
    with a NaN component (as in torch, where the NaN reaches the answer; tl.minimum/maximum would drop it).

    Channels of a ray, from its box entry x = o + t_entry d: RAY: the foot point x - s0 d (3), s0 = x.d, d (3);
    else x (3), d (3). Encoding column i is channel chan[i] as given, or sin(channel * scale[i] + phase[i]), or 0
    (kind[i]). Hit: visible (logit > 0 with two outputs, else distance < clamp_hit), t > min_hit and
    t <= the box exit."""
    rows = tl.program_id(0).to(tl.int64) * BLOCK + tl.arange(0, BLOCK)
    live = rows < n_rows
    ox = tl.load(o_ptr + rows * 3, mask=live, other=0.0)
    oy = tl.load(o_ptr + rows * 3 + 1, mask=live, other=0.0)
    oz = tl.load(o_ptr + rows * 3 + 2, mask=live, other=0.0)
    dx = tl.load(d_ptr + rows * 3, mask=live, other=1.0)
    dy = tl.load(d_ptr + rows * 3 + 1, mask=live, other=0.0)
    dz = tl.load(d_ptr + rows * 3 + 2, mask=live, other=0.0)
    ex, lx = _slab(ox, dx, half)
    ey, ly = _slab(oy, dy, half)
    ez, lz = _slab(oz, dz, half)
    t_exit = tl.minimum(tl.minimum(lx, ly), lz)
    t_entry = tl.maximum(tl.maximum(tl.maximum(ex, ey), ez), 0.0)
    meets = (t_exit >= t_entry) & (ox == ox) & (oy == oy) & (oz == oz) & (dx == dx) & (dy == dy) & (dz == dz)
    xx, xy, xz = ox + t_entry * dx, oy + t_entry * dy, oz + t_entry * dz
    s0 = xx * dx + xy * dy + xz * dz
    if RAY:
        c0, c1, c2, c3, c4, c5, c6 = xx - s0 * dx, xy - s0 * dy, xz - s0 * dz, s0, dx, dy, dz
    else:
        c0, c1, c2, c3, c4, c5, c6 = xx, xy, xz, dx, dy, dz, dz
    k = tl.arange(0, K0)
    chan = tl.load(chan_ptr + k)[None, :]
    v = tl.where(chan == 0, c0[:, None], c6[:, None])
    v = tl.where(chan == 1, c1[:, None], v)
    v = tl.where(chan == 2, c2[:, None], v)
    v = tl.where(chan == 3, c3[:, None], v)
    v = tl.where(chan == 4, c4[:, None], v)
    v = tl.where(chan == 5, c5[:, None], v)
    arg = v * tl.load(scale_ptr + k)[None, :] + tl.load(phase_ptr + k)[None, :]
    if INTERP:  # the interpreter has no fast sine
        wave = tl.sin(arg)
    else:
        # sin.approx: ~1e-6 absolute within +-100 pi, ~1e-4 at the ~1700 of 10 octaves: below the inputs' bf16 step
        wave = libdevice.fast_sinf(arg)
    kind = tl.load(kind_ptr + k)[None, :]
    x = tl.where(kind == 0, v, tl.where(kind == 1, wave, 0.0)).to(tl.bfloat16)
    h = _body(x, w0_ptr, b0_ptr, wh_ptr, bh_ptr, K0, WIDTH, HIDDEN, INTERP)
    dist = _head(h, wo_ptr, bo_ptr, 0, WIDTH)
    if RAY:
        dist = dist - s0
    dist = tl.maximum(dist, 0.0)
    if N_OUT == 2:
        visible = _head(h, wo_ptr, bo_ptr, 1, WIDTH) > 0.0
    else:
        visible = dist < clamp_hit
    t = t_entry + dist
    hit = visible & meets & (t > min_hit) & (t <= t_exit)
    tl.store(t_ptr + rows, tl.where(hit, t, float("inf")), mask=live)


_SHAPE_KEY = ["K0", "WIDTH", "HIDDEN", "N_OUT", "large"]
_MLP, _DEPTH = _tuned(_mlp_kernel, _SHAPE_KEY), _tuned(_depth_kernel, _SHAPE_KEY + ["RAY"])


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


def _launch(kernel, n: int, device: torch.device, *args, **constexprs) -> None:
    """kernel over cdiv(n, BLOCK) programs on device's CUDA device and stream (Triton launches on the current
    one), autotuned; interpreted: 128 rows a program."""
    fixed = dict(BLOCK=128, num_warps=4) if INTERPRETED else {}
    with torch.cuda.device(device) if device.type == "cuda" else contextlib.nullcontext():
        kernel[lambda meta: (triton.cdiv(n, meta["BLOCK"]),)](*args, INTERP=INTERPRETED, **constexprs, **fixed)


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

    def weights(self) -> tuple[torch.Tensor, ...]:
        """The kernels' weight arguments, in their order."""
        return self.w0, self.b0, self.wh, self.bh, self.wo, self.bo

    def shape(self) -> dict[str, int]:
        """The kernels' network constexprs."""
        return dict(K0=self.k0, WIDTH=self.width, HIDDEN=self.hidden, N_OUT=self.n_out)

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
            _launch(_MLP, n, x.device, x, *self.weights(), y, n, int(n >= SMALL), **self.shape())
        return y


def encoding_columns(net: DDFNet, k0: int) -> tuple[list[int], list[float], list[float], list[int]]:
    """The kernel's tables (k0 entries each) that rebuild DDFNet.features from the ray's channels (see
    _depth_kernel): channel, scale, phase and kind (IDENTITY, SINE, PAD) of every encoding column, in
    features' order (FourierFeatures: the channels, then every channel's sines, then its cosines)."""
    columns = []  # (channel, scale, phase, kind)
    n_pos = 4 if net.param == "ray" else 3
    for pe, channels in ((net.pos_pe, range(n_pos)), (net.dir_pe, range(n_pos, n_pos + 3))):
        columns += [(c, 1.0, 0.0, IDENTITY) for c in channels]
        columns += [(c, f, shift, SINE) for shift in (0.0, math.pi / 2) for c in channels for f in pe.freqs.tolist()]
    columns += [(0, 0.0, 0.0, PAD)] * (k0 - len(columns))
    chan, scale, phase, kind = (list(v) for v in zip(*columns))
    return chan, scale, phase, kind


def supported_depth(net: DDFNet) -> str | None:
    """None if FusedDepth can answer for net, else why not (one line)."""
    if net.direction != "vector":
        return "only unit-vector directions are encoded in the kernel (not angles)"
    return supported(net)


class FusedDepth:
    """A DDF's depth as one kernel: (origins (N,3), unit directions (N,3)) float32 on its device -> t (N,)
    float32, inf on a miss; the hit rule of ddfbench.models.ddf.infer.DDFDepth (rep's box, min_hit_distance, and the
    visibility head or the clamp ratio)."""

    def __init__(self, rep):
        why = supported_depth(rep.net)
        if why:
            raise ValueError(f"FusedDepth: {why}")
        self.mlp = FusedMLP(rep.net)
        dev = self.mlp.w0.device
        chan, scale, phase, kind = encoding_columns(rep.net, self.mlp.k0)
        self.chan = torch.tensor(chan, dtype=torch.int32, device=dev)
        self.scale = torch.tensor(scale, dtype=torch.float32, device=dev)
        self.phase = torch.tensor(phase, dtype=torch.float32, device=dev)
        self.kind = torch.tensor(kind, dtype=torch.int32, device=dev)
        self.ray = rep.net.param == "ray"
        self.half, self.min_hit = float(rep.domain), float(rep.cfg["min_hit_distance"])
        self.clamp_hit = float(rep.cfg["clamp_hit_ratio"]) * float(rep.cfg["delta"])

    def __call__(self, o: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
        if o.device != self.chan.device or d.device != o.device:
            raise ValueError(f"FusedDepth: rays on {o.device} and {d.device}, weights on {self.chan.device}")
        o, d = o.float().contiguous(), d.float().contiguous()
        n = len(o)
        t = torch.empty(n, device=o.device, dtype=torch.float32)
        if n:
            _launch(_DEPTH, n, o.device, o, d, self.chan, self.scale, self.phase, self.kind, *self.mlp.weights(), t,
                    n, int(n >= SMALL), self.half, self.min_hit, self.clamp_hit, RAY=self.ray, **self.mlp.shape())
        return t


def config(kernel_name: str) -> str:
    """The block size and warps the autotuner chose last for kernel "mlp" or "depth" (or why there is none)."""
    if INTERPRETED:
        return "interpreted: BLOCK 128"
    best = getattr({"mlp": _MLP, "depth": _DEPTH}[kernel_name], "best_config", None)
    return f"BLOCK {best.kwargs['BLOCK']}, {best.num_warps} warps" if best is not None else "not tuned yet"
