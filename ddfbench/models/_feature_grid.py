"""A learned multiresolution 3D feature grid, hashed on its fine levels (Instant-NGP, Mueller et al. 2022): one
encoding shared by the families that read it (the DDF's line encoding, ddfbench.models.ddf.line_grid, and the
hash-grid neural SDF, ddfbench.models.neural_sdf).

Levels l = 0..L-1 have resolution round(base * growth^l) cells a side over [-half, half]^3 with
growth = (finest / base)^(1/(L-1)); a level whose (res+1)^3 nodes fit the table is indexed densely
(x + (res+1) y + (res+1)^2 z), a finer one by the spatial hash x * 1 ^ y * 2654435761 ^ z * 805459861 mod T
(T = 2^log2_size entries a level). A point's features at a level are the trilinear blend of its cell's 8 nodes.
Table init uniform(-1e-4, 1e-4). Points beyond the box are clamped onto its faces.
"""

from __future__ import annotations

from typing import Any, Mapping

import torch
from torch import nn

from ddfbench.core.errors import InputError

PRIMES = (1, 2654435761, 805459861)
MAX_LOG2_SIZE = 24


def check_keys(cfg: Mapping[str, Any], prefix: str) -> None:
    """One-line InputError naming the key when a grid's `<prefix>levels, _features, _base, _finest, _log2_size`
    are not positive integers, the table exceeds 2^24 entries a level, or finest < base."""
    for key in ("levels", "features", "base", "finest", "log2_size"):
        if int(cfg[prefix + key]) < 1:
            raise InputError(f"model.{prefix}{key} {cfg[prefix + key]}: must be a positive integer")
    if int(cfg[prefix + "log2_size"]) > MAX_LOG2_SIZE:
        raise InputError(f"model.{prefix}log2_size {cfg[prefix + 'log2_size']}: at most {MAX_LOG2_SIZE} "
                         f"(2^{MAX_LOG2_SIZE} entries a level)")
    if int(cfg[prefix + "finest"]) < int(cfg[prefix + "base"]):
        raise InputError(f"model.{prefix}finest {cfg[prefix + 'finest']}: must be >= {prefix}base {cfg[prefix + 'base']}")


def _corners(v: torch.Tensor, op) -> torch.Tensor:
    """Per-axis pairs v (L,M,3,2) -> the 8 corner combinations op(op(x_i, y_j), z_k) (L,M,8), i major."""
    return op(op(v[:, :, 0, :, None, None], v[:, :, 1, None, :, None]), v[:, :, 2, None, None, :]).flatten(2)


class FeatureGrid(nn.Module):
    """points (M,3) -> features (M, levels, features) by `lookup`; its one parameter is `table`
    (levels * 2^log2_size, features)."""

    def __init__(self, levels: int, features: int, base: int, finest: int, log2_size: int, half: float):
        super().__init__()
        self.levels, self.features, self.half = int(levels), int(features), float(half)
        self.size = 2 ** int(log2_size)
        growth = (finest / base) ** (1.0 / max(levels - 1, 1))
        res = [max(1, round(base * growth**level)) for level in range(levels)]
        self.register_buffer("res", torch.tensor(res, dtype=torch.int64), persistent=False)
        self.n_dense = sum((r + 1) ** 3 <= self.size for r in res)  # res grows, so the dense levels come first
        side = torch.tensor([[1, r + 1, (r + 1) ** 2] for r in res[: self.n_dense]], dtype=torch.int32).reshape(-1, 3)
        self.register_buffer("dense_mult", side[:, None, :, None], persistent=False)                 # (Ld,1,3,1)
        self.register_buffer("primes", torch.tensor(PRIMES, dtype=torch.int64)[:, None], persistent=False)  # (3,1)
        self.register_buffer("offsets", (torch.arange(levels, dtype=torch.int64) * self.size)[:, None, None],
                             persistent=False)                                                       # (L,1,1)
        self.table = nn.Parameter(torch.empty(levels * self.size, features).uniform_(-1e-4, 1e-4))

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
