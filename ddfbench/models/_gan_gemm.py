"""The GAN-SDF generator evaluated as matrix products, for inference: the same function as
gan_sdf.ConvField(3, Tanh, ReLU) to float tolerance (tests/test_gan_gemm.py), with three exact rewrites:

1. lift then conv1 is affine in the point: one (3 -> L1*C1) matrix product, written channels last;
2. the B points of a chunk lie end to end as one sequence of B*L1 rows, channels last; every window that
   conv2 and the two max pools read for a point lies inside that point's block of L1 rows, and the windows
   that straddle two blocks are computed and never read (8 of 250 rows, 3 %);
3. conv2 (kernel K2) is K2 accumulated (rows x C1) @ (C1 x C2) products of row-shifted views of one
   buffer: no column (im2col) copy. The head reads each point's block through a strided view.

The weights are packed from the module at every call (~0.2 ms), so the values always follow the module.
The buffers (~96 KB a point of capacity: ~1.5 MB at 16 points a call, ~6 GB at 65,536) are kept between
calls and only grow, up to the chunk asked for; a call allocates its output and, for a last chunk shorter
than the capacity, only views. Inference only (nothing keeps a graph), and not thread-safe: two threads
evaluating through one GemmGenerator would write the same buffers.
"""

from __future__ import annotations

import torch
from torch import nn


class _Packed:
    """The generator's weights as the rewrite uses them, and its sizes: l1 rows a point (250), c1 / c2
    channels (16 / 32), pool window, conv2 taps (5), l2_valid head positions a point (242)."""

    def __init__(self, net: nn.Module):
        _check_structure(net)
        w_lift, b_lift = net.lift.weight, net.lift.bias                     # (L0, 3), (L0,)
        w1, b1 = net.conv1.weight[:, 0, :], net.conv1.bias                  # (C1, K1), (C1,)
        k1 = w1.shape[1]
        self.l1, self.c1, self.c2 = w_lift.shape[0] - k1 + 1, w1.shape[0], net.conv2.out_channels
        self.pool = _pool_window(net.pool)
        # y[t, c] = sum_k w1[c, k] (w_lift[t + k] . x + b_lift[t + k]) + b1[c], rows (t, c)
        lift_windows = w_lift.unfold(0, k1, 1)                              # (L1, 3, K1)
        self.w_fused = torch.einsum("tik,ck->tci", lift_windows, w1).reshape(-1, w_lift.shape[1]).T.contiguous()
        self.b_fused = (b_lift.unfold(0, k1, 1) @ w1.T + b1).reshape(-1)    # (L1 * C1,)
        self.w2 = [net.conv2.weight[:, :, k].T.contiguous() for k in range(net.conv2.kernel_size[0])]  # K2 x (C1, C2)
        self.b2 = net.conv2.bias
        self.l2_valid = self.l1 - 2 * (self.pool - 1) - (len(self.w2) - 1)
        w_head = net.head.weight.reshape(self.c2, -1)                       # (C2, L2')
        if w_head.shape[1] != self.l2_valid:
            raise ValueError(f"GemmGenerator: the head reads {w_head.shape[1]} positions, the stack gives {self.l2_valid}")
        self.w_head = w_head.T.reshape(-1).contiguous()                     # (L2' * C2,) in (t, c) order
        self.b_head = net.head.bias

    def buffer_shapes(self, points: int) -> dict[str, tuple[int, int]]:
        """Rows x channels of each buffer for `points` points a chunk."""
        n, shrink = points * self.l1, self.pool - 1
        z_rows = n - shrink - (len(self.w2) - 1)
        return {"y": (points, self.l1 * self.c1), "h": (n - shrink, self.c1), "z": (z_rows, self.c2),
                "p": (z_rows - shrink, self.c2)}


def _pool_window(pool: nn.MaxPool1d) -> int:
    return pool.kernel_size if isinstance(pool.kernel_size, int) else pool.kernel_size[0]


def _check_structure(net: nn.Module) -> None:
    """ValueError unless net is the generator this rewrite assumes: Tanh then ReLU, unpadded stride-1
    single-group convolutions (conv1 from one channel), and one stride-1 unpadded max pool of window >= 2."""
    convs_plain = all(c.stride == (1,) and c.padding == (0,) and c.dilation == (1,) and c.groups == 1
                      for c in (net.conv1, net.conv2)) and net.conv1.in_channels == 1
    pool = net.pool
    pool_plain = (pool.stride in (1, (1,)) and pool.padding in (0, (0,)) and pool.dilation in (1, (1,))
                  and not pool.ceil_mode and _pool_window(pool) >= 2)
    acts = isinstance(net.act1, nn.Tanh) and isinstance(net.act2, nn.ReLU)
    if not (convs_plain and pool_plain and acts):
        raise ValueError("GemmGenerator: needs the generator's stack (Tanh then ReLU, unpadded stride-1 convolutions "
                         "and max pools)")


class _Views:
    """The in-place views of one chunk of b points over the buffers, sliced once a call: y (b, L1*C1); each pool's
    row-shifted sources and destination; conv2's shifted inputs; the head's per-point blocks (b, L2'*C2)
    with a row stride of L1*C2."""

    def __init__(self, packed: _Packed, buffers: dict[str, torch.Tensor], b: int):
        shapes = packed.buffer_shapes(b)
        h, z, p = (buffers[k][: shapes[k][0]] for k in ("h", "z", "p"))
        self.y, self.h, self.z, self.p = buffers["y"][:b], h, z, p
        y_rows = self.y.view(-1, packed.c1)
        self.y_shifts = [y_rows[j : j + len(h)] for j in range(packed.pool)]
        self.h_shifts = [h[k : k + len(z)] for k in range(len(packed.w2))]
        self.z_shifts = [z[j : j + len(p)] for j in range(packed.pool)]
        self.blocks = p.as_strided((b, packed.l2_valid * packed.c2), (packed.l1 * packed.c2, 1))


def _max_pool(shifts: list[torch.Tensor], dst: torch.Tensor) -> torch.Tensor:
    """dst = the elementwise max of the pool window's row-shifted views (at least 2), in place."""
    torch.maximum(shifts[0], shifts[1], out=dst)
    for src in shifts[2:]:
        torch.maximum(dst, src, out=dst)
    return dst


class GemmGenerator:
    """Evaluates a generator module (M, 3) -> (M,) without autograd, holding the buffers between calls."""

    def __init__(self):
        self._buffers: dict[str, torch.Tensor] = {}
        self._key: tuple = ()  # (capacity in points, device, dtype) of the buffers

    def _buffers_for(self, packed: _Packed, points: int, device: torch.device, dtype: torch.dtype) -> dict:
        capacity, old_device, old_dtype = self._key or (0, None, None)
        same_kind = (device, dtype) == (old_device, old_dtype)
        if not same_kind or points > capacity:
            capacity = max(points, capacity) if same_kind else points
            self._buffers = {}  # the old ones go before the new ones are allocated
            with torch.inference_mode(False):  # plain tensors: written in place under no_grad or inference mode
                self._buffers = {k: torch.empty(s, device=device, dtype=dtype)
                                 for k, s in packed.buffer_shapes(capacity).items()}
            self._key = (capacity, device, dtype)
        return self._buffers

    @staticmethod
    def _chunk(packed: _Packed, x: torch.Tensor, v: _Views, out: torch.Tensor) -> None:
        """One chunk (b, 3) -> out (b,) without the head's bias, through the views of b points."""
        torch.addmm(packed.b_fused, x, packed.w_fused, out=v.y)
        _max_pool(v.y_shifts, v.h).tanh_()
        torch.addmm(packed.b2, v.h_shifts[0], packed.w2[0], out=v.z)
        for h_k, w_k in zip(v.h_shifts[1:], packed.w2[1:]):
            v.z.addmm_(h_k, w_k)
        _max_pool(v.z_shifts, v.p).relu_()
        torch.mv(v.blocks, packed.w_head, out=out)

    def __call__(self, net: nn.Module, points: torch.Tensor, chunk: int) -> torch.Tensor:
        """net at points (M, 3) -> (M,), `chunk` (>= 1) points a matrix product; points on net's device and
        of its dtype."""
        if chunk < 1:
            raise ValueError(f"GemmGenerator: chunk {chunk}: must be >= 1 point a call")
        with torch.no_grad():
            out = points.new_empty(points.shape[0])
            if not len(points):
                return out
            packed = _Packed(net)
            b = min(chunk, len(points))
            buffers = self._buffers_for(packed, b, points.device, points.dtype)
            full = _Views(packed, buffers, b)
            for s in range(0, len(points), chunk):
                x = points[s : s + chunk]
                self._chunk(packed, x, full if len(x) == b else _Views(packed, buffers, len(x)), out[s : s + chunk])
            return out.add_(packed.b_head)
