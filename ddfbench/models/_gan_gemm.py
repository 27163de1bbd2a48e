"""The GAN-SDF generator evaluated as matrix products, for inference: the same function as
gan_sdf.ConvField(3, Tanh, ReLU) to float tolerance (tests/test_gan_gemm.py), with three exact rewrites:

1. lift then conv1 is affine in the point: one (3 -> L1*C1) matrix product, written channels last;
2. the B points of a chunk lie end to end as one sequence of B*L1 positions (rows), channels last; every
   window that conv2 and the two max pools read for a point lies inside that point's block of L1 rows,
   and the windows that straddle two blocks are computed and never read (8 of 250 rows, 3 %);
3. conv2 (kernel K2) is K2 accumulated (rows x C1) @ (C1 x C2) products of row-shifted views of one
   buffer: no column (im2col) copy. The head reads each point's block through a strided view.

Buffers are allocated once per (device, chunk) and written in place, so a call allocates nothing but
its output. The packed weights follow the module: they are rebuilt when a parameter is replaced or
changed in place (its data pointer or version counter moves). Inference only: nothing here keeps a graph.
"""

from __future__ import annotations

import torch
from torch import nn


def weights_key(net: nn.Module) -> tuple:
    """What identifies the current weights: each parameter's storage, device and in-place version."""
    return tuple((p.data_ptr(), p.device, p._version) for p in net.parameters())


class _Views:
    """The in-place views of one chunk of b points over the workspace buffers (rows = b * L1), sliced once:
    y (b, L1*C1) and its row view; each pool's shifted sources and destination; conv2's shifted inputs; the
    head's per-point blocks (b, L2'*C2) with a row stride of L1*C2."""

    def __init__(self, gen: "GemmGenerator", ws: dict[str, torch.Tensor], b: int):
        shrink, taps = gen.pool - 1, len(gen.w2)
        n = b * gen.rows
        m = n - shrink - (taps - 1)
        self.y = ws["y"][:b]
        rows = self.y.view(n, gen.c1)
        self.h, self.z, self.p = ws["h"][: n - shrink], ws["z"][:m], ws["p"][: m - shrink]
        self.y_shifts = [rows[j : j + n - shrink] for j in range(gen.pool)]
        self.h_shifts = [self.h[k : k + m] for k in range(taps)]
        self.z_shifts = [self.z[j : j + m - shrink] for j in range(gen.pool)]
        self.blocks = self.p.as_strided((b, gen.valid * gen.c2), (gen.rows * gen.c2, 1))


def _max_pool(shifts: list[torch.Tensor], dst: torch.Tensor) -> torch.Tensor:
    """dst = the elementwise max of the pool window's row-shifted views (at least 2), in place."""
    torch.maximum(shifts[0], shifts[1], out=dst)
    for src in shifts[2:]:
        torch.maximum(dst, src, out=dst)
    return dst


class GemmGenerator:
    """Evaluates a ConvField generator (M, 3) -> (M,) in chunks of `chunk` points, with no grad."""

    def __init__(self, net: nn.Module):
        if not (isinstance(net.act1, nn.Tanh) and isinstance(net.act2, nn.ReLU)):
            raise TypeError("GemmGenerator: the generator's activations are Tanh then ReLU")
        self.key = weights_key(net)
        self.pool = net.pool.kernel_size if isinstance(net.pool.kernel_size, int) else net.pool.kernel_size[0]
        if net.pool.stride not in (1, (1,)) or self.pool < 2:
            raise TypeError("GemmGenerator: the max pools have stride 1 and a window of 2 or more")
        with torch.no_grad():
            w_lift, b_lift = net.lift.weight, net.lift.bias                    # (L0, 3), (L0,)
            w1, b1 = net.conv1.weight[:, 0, :], net.conv1.bias                 # (C1, K1), (C1,)
            k1 = w1.shape[1]
            self.rows = w_lift.shape[0] - k1 + 1                               # L1 = 250: rows a point
            self.c1, self.c2 = w1.shape[0], net.conv2.out_channels
            # y[t, c] = sum_k w1[c, k] (w_lift[t + k] . x + b_lift[t + k]) + b1[c]
            lift_windows = w_lift.unfold(0, k1, 1)                             # (L1, 3, K1)
            self.a = torch.einsum("tik,ck->tci", lift_windows, w1).reshape(-1, w_lift.shape[1]).T.contiguous()
            self.a0 = (b_lift.unfold(0, k1, 1) @ w1.T + b1).reshape(-1).contiguous()  # (L1 * C1,)
            self.w2 = [net.conv2.weight[:, :, k].T.contiguous() for k in range(net.conv2.kernel_size[0])]  # K2 x (C1, C2)
            self.b2 = net.conv2.bias.clone()
            self.valid = self.rows - 2 * (self.pool - 1) - (len(self.w2) - 1)  # L2' = 242 head positions
            w_head = net.head.weight.reshape(self.c2, -1)                      # (C2, L2')
            if w_head.shape[1] != self.valid:
                raise TypeError(f"GemmGenerator: head reads {w_head.shape[1]} positions, the stack gives {self.valid}")
            self.w_head = w_head.T.reshape(-1).contiguous()                    # (L2' * C2,) in (t, c) order
            self.b_head = net.head.bias.clone()
        self._buffers: dict[tuple, tuple[dict[str, torch.Tensor], _Views]] = {}

    def _full_views(self, chunk: int, device: torch.device, dtype: torch.dtype) -> tuple[dict, _Views]:
        """(workspace buffers, views of a full chunk) for chunk points a call; one workspace is kept."""
        key = (chunk, device, dtype)
        if key not in self._buffers:
            n, shrink = chunk * self.rows, self.pool - 1
            z_rows = n - shrink - (len(self.w2) - 1)
            new = lambda *shape: torch.empty(shape, device=device, dtype=dtype)  # noqa: E731
            ws = {"y": new(chunk, self.rows * self.c1), "h": new(n - shrink, self.c1),
                  "z": new(z_rows, self.c2), "p": new(z_rows - shrink, self.c2)}
            self._buffers = {key: (ws, _Views(self, ws, chunk))}
        return self._buffers[key]

    def _chunk(self, x: torch.Tensor, v: _Views, out: torch.Tensor) -> None:
        """One chunk (b, 3) -> out (b,) without the head's bias, through the views of b points."""
        torch.addmm(self.a0, x, self.a, out=v.y)
        _max_pool(v.y_shifts, v.h).tanh_()
        torch.addmm(self.b2, v.h_shifts[0], self.w2[0], out=v.z)
        for h_k, w_k in zip(v.h_shifts[1:], self.w2[1:]):
            v.z.addmm_(h_k, w_k)
        _max_pool(v.z_shifts, v.p).relu_()
        torch.mv(v.blocks, self.w_head, out=out)

    def __call__(self, points: torch.Tensor, chunk: int) -> torch.Tensor:
        """G at points (M, 3) float -> (M,), `chunk` points a matrix product."""
        out = points.new_empty(points.shape[0])
        if not len(points):
            return out
        ws, full = self._full_views(min(chunk, len(points)), points.device, points.dtype)
        with torch.no_grad():
            for s in range(0, len(points), chunk):
                x = points[s : s + chunk]
                self._chunk(x, full if len(x) == len(full.y) else _Views(self, ws, len(x)), out[s : s + chunk])
            return out.add_(self.b_head)


def current(cached: GemmGenerator | None, net: nn.Module) -> GemmGenerator:
    """`cached` if it was packed from net's current weights, else a GemmGenerator packed anew."""
    return cached if cached is not None and cached.key == weights_key(net) else GemmGenerator(net)
