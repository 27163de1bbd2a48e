"""Multiresolution grid features read at points along a line: the DDF's optional line encoding.

A DDF answers a line (foot point p, unit direction d) in one query. A positional encoding of p and d
gives the MLP no local capacity: every weight serves every line. This encoding gives it a learned
3D feature grid (multiresolution, hashed on the fine levels as in Instant-NGP, Mueller et al. 2022)
read at K points spaced evenly over the line's chord through the field box, concatenated in order
along the line (as a light-field network reads points sampled along its ray, e.g. R2L, Wang et al.
2022). The MLP then sees where along the line the grid holds surface-like features and decodes the
hit from them; the query stays one network evaluation per ray (K*L trilinear lookups and one MLP).

The grid itself (levels, dense and hashed indexing, trilinear lookup) is ddfbench.models._feature_grid's,
shared with the hash-grid neural SDF.
"""

from __future__ import annotations

import math

import torch

from ddfbench.core.geometry import ray_box
from ddfbench.models._feature_grid import FeatureGrid

LOOKUP_CHUNK = 65536  # points per lookup call: its int64 corner indices take levels * 8 * 8 bytes a point


class LineGrid(FeatureGrid):
    """(foot (N,3), unit d (N,3)) -> features (N, points * levels * features + 2).

    The last two channels are the chord's ends (line coordinates u_in, u_out of the box, unit-cube
    units), so the MLP knows where the K points lie along the line.
    """

    def __init__(self, points: int, levels: int, features: int, base: int, finest: int, log2_size: int,
                 half: float):
        super().__init__(levels, features, base, finest, log2_size, half)
        self.points = int(points)

    def out_dim(self) -> int:
        return self.points * self.levels * self.features + 2

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
