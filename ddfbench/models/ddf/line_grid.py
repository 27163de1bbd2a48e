"""Multiresolution grid features read at points along a line: the DDF's optional line encoding.

A DDF answers a line (foot point p, unit direction d) in one query. A positional encoding of p and d
gives the MLP no local capacity: every weight serves every line. This encoding gives it a learned
3D feature grid (multiresolution, hashed on the fine levels as in Instant-NGP, Mueller et al. 2022)
read at K points spaced evenly over the line's chord through the field box, concatenated in order
along the line (as a light-field network reads points sampled along its ray, e.g. R2L, Wang et al.
2022). The MLP then sees where along the line the grid holds surface-like features and decodes the
hit from them; the query stays one network evaluation per ray (K*L trilinear lookups and one MLP).

Levels l = 0..L-1 have resolution round(base * growth^l) cells a side over [-half, half]^3 with
growth = (finest / base)^(1/(L-1)); a level whose (res+1)^3 nodes fit the table is indexed densely,
a finer one by the spatial hash of Instant-NGP (x * 1 ^ y * 2654435761 ^ z * 805459861, mod T;
T a power of two).
Table init uniform(-1e-4, 1e-4). Points beyond the box are clamped onto its faces.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from ddfbench.core.geometry import ray_box

_PRIMES = (1, 2654435761, 805459861)
LOOKUP_CHUNK = 65536  # points per lookup call: its int64 corner indices take levels * 8 * 8 bytes a point


def _corners(v: torch.Tensor, op) -> torch.Tensor:
    """Per-axis pairs v (L,M,3,2) -> the 8 corner combinations op(op(x_i, y_j), z_k) (L,M,8), i major."""
    return op(op(v[:, :, 0, :, None, None], v[:, :, 1, None, :, None]), v[:, :, 2, None, None, :]).flatten(2)


class LineGrid(nn.Module):
    """(foot (N,3), unit d (N,3)) -> features (N, points * levels * features + 2).

    The last two channels are the chord's ends (line coordinates u_in, u_out of the box, unit-cube
    units), so the MLP knows where the K points lie along the line.
    """

    def __init__(self, points: int, levels: int, features: int, base: int, finest: int, log2_size: int,
                 half: float):
        super().__init__()
        self.points, self.levels, self.features, self.half = int(points), int(levels), int(features), float(half)
        self.size = 2 ** int(log2_size)
        growth = (finest / base) ** (1.0 / max(levels - 1, 1))
        res = [max(1, round(base * growth**level)) for level in range(levels)]
        self.register_buffer("res", torch.tensor(res, dtype=torch.int64), persistent=False)
        self.n_dense = sum((r + 1) ** 3 <= self.size for r in res)  # res grows, so the dense levels come first
        side = torch.tensor([[1, r + 1, (r + 1) ** 2] for r in res[: self.n_dense]], dtype=torch.int32).reshape(-1, 3)
        self.register_buffer("dense_mult", side[:, None, :, None], persistent=False)                 # (Ld,1,3,1)
        self.register_buffer("primes", torch.tensor(_PRIMES, dtype=torch.int64)[:, None], persistent=False)  # (3,1)
        self.register_buffer("offsets", (torch.arange(levels, dtype=torch.int64) * self.size)[:, None, None],
                             persistent=False)                                                       # (L,1,1)
        self.table = nn.Parameter(torch.empty(levels * self.size, features).uniform_(-1e-4, 1e-4))

    def out_dim(self) -> int:
        return self.points * self.levels * self.features + 2

    def lookup(self, q: torch.Tensor) -> torch.Tensor:
        """Trilinear features of points q (M,3) at every level -> (M, levels, features).

        Per level and axis the two node coordinates and weights of each point (L,M,3,2) are combined
        into the 8 corners by broadcasting: x + side*y + side^2*z on the dense levels (the coarse ones,
        int32), the hash's XOR on the others (int64: node < 2^31 times a prime < 2^32 cannot overflow).
        """
        unit = ((q.clamp(-self.half, self.half) + self.half) / (2 * self.half))[None]  # (1,M,3) in [0,1]
        res = self.res[:, None, None]                                                  # (L,1,1)
        c = unit * res                                                                 # (L,M,3)
        i0 = torch.minimum(c.detach().nan_to_num(0.0).floor().clamp_min(0).int(), res.int() - 1)  # NaN: node 0, NaN weights
        w = c - i0
        nodes = torch.stack([i0, i0 + 1], -1)                                          # (L,M,3,2) int32
        cw = _corners(torch.stack([1 - w, w], -1), torch.mul)                          # (L,M,8)
        nd = self.n_dense
        idx = torch.cat([_corners(nodes[:nd] * self.dense_mult, torch.add).long(),
                         _corners(nodes[nd:].long() * self.primes, torch.bitwise_xor) & (self.size - 1)])
        idx = idx + self.offsets                                                       # (L,M,8) int64 (fast index_add)
        feats = self.table.index_select(0, idx.flatten()).view(*idx.shape, self.features)  # (L,M,8,F)
        return (cw[..., None] * feats).sum(2).transpose(0, 1)                              # (M,L,F)

    def forward(self, foot: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
        u_in, u_out = ray_box(foot, d, self.half)
        u_in = u_in.clamp(-math.sqrt(3) * self.half, math.sqrt(3) * self.half)
        u_out = torch.maximum(u_out.clamp(-math.sqrt(3) * self.half, math.sqrt(3) * self.half), u_in)
        frac = (torch.arange(self.points, dtype=foot.dtype, device=foot.device) + 0.5) / self.points
        u = u_in[:, None] + frac * (u_out - u_in)[:, None]                                   # (N,K)
        q = foot[:, None, :] + u[..., None] * d[:, None, :]                                  # (N,K,3)
        flat = q.reshape(-1, 3)
        feats = torch.cat([self.lookup(flat[s : s + LOOKUP_CHUNK]) for s in range(0, len(flat), LOOKUP_CHUNK)]
                          or [flat.new_zeros(0, self.levels, self.features)]).reshape(len(foot), -1)
        return torch.cat([feats, u_in[:, None], u_out[:, None]], -1)
