"""The DDF network phi(x, d) -> (distance, visibility logit) and the checked model config it is built from."""

from __future__ import annotations

import math
from typing import Any, Mapping

import torch
from torch import nn

from ddfbench.core import plugins
from ddfbench.core.errors import InputError
from ddfbench.core.geometry import BOX_HALF, FourierFeatures
from ddfbench.models import _feature_grid as feature_grid
from ddfbench.models.ddf.line_grid import LineGrid

_CHOICES = {"activation": ("relu", "softplus"), "direction": ("vector", "angles"), "param": ("point", "ray"),
            "visibility": ("head", "clamp"), "loss": ("l1", "clamp", "clamp_misses"), "storage_dtype": ("float32", "float16"),
            "mesh_field": ("signed", "udf")}


def checked_config(cfg: Mapping[str, Any]) -> dict[str, Any]:
    """conf/model/ddf.yaml overlaid by cfg (strict, see ddfbench.core.plugins), with the values checked."""
    out = plugins.family_config("ddf", cfg)
    for key, allowed in _CHOICES.items():
        if out[key] not in allowed:
            raise InputError(f"model.{key} '{out[key]}': unknown (one of {', '.join(allowed)})")
    for key in ("width", "depth", "batch", "udf_directions", "udf_rank", "eval_batch", "mesh_directions",
                "mesh_keep", "mesh_rank", "mesh_coarse"):
        if int(out[key]) < 1:
            raise InputError(f"model.{key} {out[key]}: must be a positive integer")
    if int(out["line_grid_points"]) < 0:
        raise InputError(f"model.line_grid_points {out['line_grid_points']}: must be a non-negative integer")
    feature_grid.check_keys(out, "line_grid_")
    if not 0.0 <= float(out["entry_share"]) < 1.0:
        raise InputError(f"model.entry_share {out['entry_share']}: must be in [0, 1)")
    for key in ("mesh_band", "mesh_lipschitz"):
        if not float(out[key]) > 0:
            raise InputError(f"model.{key} {out[key]}: must be > 0")
    if out["visibility"] == "clamp" and out["loss"] == "l1":
        raise InputError("model.visibility 'clamp' needs model.loss 'clamp' or 'clamp_misses' (misses are learned as delta)")
    if out["loss"] != "l1" and not (math.isfinite(float(out["delta"])) and float(out["delta"]) > 0):
        raise InputError(f"model.delta {out['delta']}: must be finite and > 0 for the {out['loss']} loss")
    return out


class DDFNet(nn.Module):
    """phi(x, d) for x (N,3), unit d (N,3) -> (distance (N,), visibility logit (N,) or None).

    With line_grid_points K > 0 the MLP also reads LineGrid features of the line through x (grid over
    the field box [-half, half]^3)."""

    def __init__(self, cfg: Mapping[str, Any], half: float = BOX_HALF):
        super().__init__()
        self.param, self.direction = cfg["param"], cfg["direction"]
        self.pos_pe, self.dir_pe = FourierFeatures(cfg["pos_freqs"], math.pi), FourierFeatures(cfg["dir_freqs"], math.pi)
        n_pos = self.pos_pe.out_dim(4 if self.param == "ray" else 3)
        n_dir = self.dir_pe.out_dim(3 if self.direction == "vector" else 2)
        n_out = 2 if cfg["visibility"] == "head" else 1
        act = {"relu": nn.ReLU, "softplus": lambda: nn.Softplus(beta=100)}[cfg["activation"]]
        self.grid = (LineGrid(cfg["line_grid_points"], cfg["line_grid_levels"], cfg["line_grid_features"],
                              cfg["line_grid_base"], cfg["line_grid_finest"], cfg["line_grid_log2_size"], half)
                     if int(cfg["line_grid_points"]) > 0 else None)
        layers, n_in = [], n_pos + n_dir + (self.grid.out_dim() if self.grid is not None else 0)
        for _ in range(int(cfg["depth"])):
            lin = nn.Linear(n_in, int(cfg["width"]))
            layers += [nn.utils.parametrizations.weight_norm(lin) if cfg["weight_norm"] else lin, act()]
            if cfg["dropout"] > 0:
                layers.append(nn.Dropout(float(cfg["dropout"])))
            n_in = int(cfg["width"])
        self.body = nn.Sequential(*layers)
        self.out = nn.Linear(n_in, n_out)

    def features(self, x: torch.Tensor, d: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        """The MLP's input (N, n_in) of x (N,3), unit d (N,3), and the ray coordinate s0 = x.d (N,1) (None
        unless param is ray)."""
        s0 = (x * d).sum(-1, keepdim=True) if self.param == "ray" else None
        pos = torch.cat([x - s0 * d, s0], -1) if s0 is not None else x
        if self.direction == "angles":
            polar = torch.acos(d[:, 2:3].clamp(-1.0, 1.0))
            dirs = torch.cat([polar, torch.atan2(d[:, 1:2], d[:, 0:1])], -1)
        else:
            dirs = d
        inputs = [self.pos_pe(pos), self.dir_pe(dirs)]
        if self.grid is not None:
            inputs.append(self.grid(x - (x * d).sum(-1, keepdim=True) * d, d))
        return torch.cat(inputs, -1), s0

    @staticmethod
    def outputs(y: torch.Tensor, s0: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor | None]:
        """(distance (N,), visibility logit (N,) or None) from the MLP's output y (N, 1 | 2) and features' s0."""
        dist = y[:, 0] - s0[:, 0] if s0 is not None else y[:, 0]
        return dist, (y[:, 1] if y.shape[1] > 1 else None)

    def forward(self, x: torch.Tensor, d: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        feats, s0 = self.features(x, d)
        return self.outputs(self.out(self.body(feats)), s0)
