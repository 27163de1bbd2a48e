"""Neural SDF: harmonic embedding -> MLP -> signed distance, answered by sphere tracing.

Network: x (3) -> [x, sin(2^k w0 x), cos(2^k w0 x)] for k < n_harmonics (3 + 6*n_harmonics
features), and with grid_levels L > 0 the features of a learned multiresolution hash grid at x
(ddfbench.models._feature_grid, the encoding the line-grid DDF reads: L levels of grid_features, grid_base
to grid_finest cells a side over the field box, 2^grid_log2_size entries a level) -> `depth`
Linear+activation layers of `width` -> Linear -> 1 (the hash-grid SDF: a grid and a small head). Activation
softplus (softplus_beta, 100 by default) or relu. Geometric initialization (Atzmon & Lipman
2020) starts the field near the SDF of a sphere of radius `init_radius` (exactly so only in
the wide-network limit with relu; at width 128 and in our half-unit box, softplus 100 gives
a slope of about 0.5-1 and an offset of a few hundredths); the first layer's weights on the
sin/cos features start at zero so the embedding does not break that.

Losses on a batch of SDF samples (x, s) (sample_kind "sdf"):
  w_sdf      * mean |clamp(f(x), -delta, delta) - clamp(s, -delta, delta)|   (DeepSDF, delta 0.1;
               see clamped_l1 for where its gradient would vanish)
  w_surface  * mean |f(x)| over the batch's samples with |s| <= surface_tol
  w_eikonal  * mean | ||grad f(y)|| - 1 |, y = as many points uniform in the field box as the batch
               (everywhere, not only near the surface: far from the samples it keeps f from
               dipping below zero, which larger networks did as floating surfaces)
Normals of hits: autograd, one batched backward pass (counted per point).
Artifact: one torch file {"header": JSON config, "state_dict": ...}, read with weights_only=True.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import torch
from torch import nn

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import BOX_HALF, FourierFeatures
from ddfbench.core.representation import Budget, FitData, FitStats, Probe
from ddfbench.fit.train import seed_everything
from ddfbench.models import _feature_grid as feature_grid
from ddfbench.models._sdf_family import NetSDFFamily

_ARCH_KEYS = ("n_harmonics", "omega0", "width", "depth", "activation", "softplus_beta", "grid_levels", "grid_features",
              "grid_base", "grid_finest", "grid_log2_size")


class SDFNet(nn.Module):
    """[harmonic embedding, hash-grid features] -> depth x (Linear, activation) of width -> Linear -> (M,)."""

    def __init__(self, n_harmonics: int, omega0: float, width: int, depth: int, activation: str, softplus_beta: float,
                 grid_levels: int, grid_features: int, grid_base: int, grid_finest: int, grid_log2_size: int,
                 half: float = BOX_HALF):
        super().__init__()
        if activation not in ("softplus", "relu"):
            raise InputError(f"model.activation '{activation}': unknown (softplus | relu)")
        if width < 1 or depth < 1 or n_harmonics < 0 or grid_levels < 0:
            raise InputError(f"model width={width} depth={depth} n_harmonics={n_harmonics} grid_levels={grid_levels}: "
                             "width, depth >= 1, n_harmonics, grid_levels >= 0")
        self.embed = FourierFeatures(n_harmonics, omega0)
        self.grid = None
        if grid_levels:
            keys = dict(grid_levels=grid_levels, grid_features=grid_features, grid_base=grid_base,
                        grid_finest=grid_finest, grid_log2_size=grid_log2_size)
            feature_grid.check_keys(keys, "grid_")
            self.grid = feature_grid.FeatureGrid(grid_levels, grid_features, grid_base, grid_finest, grid_log2_size, half)
        n_grid = grid_levels * grid_features if self.grid is not None else 0
        dims = [self.embed.out_dim(3) + n_grid] + [width] * depth
        self.hidden = nn.ModuleList(nn.Linear(a, b) for a, b in zip(dims[:-1], dims[1:]))
        self.out = nn.Linear(width, 1)
        self.act = nn.Softplus(beta=softplus_beta) if activation == "softplus" else nn.ReLU()

    def geometric_init(self, radius: float) -> None:
        """Start near the SDF of a sphere of `radius` (SAL); the weights on the sin/cos and grid features start at zero."""
        with torch.no_grad():
            for layer in self.hidden:
                nn.init.normal_(layer.weight, 0.0, math.sqrt(2.0 / layer.out_features))
                nn.init.zeros_(layer.bias)
            self.hidden[0].weight[:, 3:] = 0.0
            nn.init.normal_(self.out.weight, math.sqrt(math.pi / self.out.in_features), 1e-4)
            self.out.bias.fill_(-radius)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.embed(x)
        if self.grid is not None:
            h = torch.cat([h, self.grid.lookup(x).flatten(1)], 1)
        for layer in self.hidden:
            h = self.act(layer(h))
        return self.out(h).squeeze(1)


def eikonal_residual(net: nn.Module, points: torch.Tensor) -> torch.Tensor:
    """mean | ||grad f|| - 1 | at points (M, 3), differentiable (create_graph)."""
    p = points.detach().requires_grad_(True)
    (grad,) = torch.autograd.grad(net(p).sum(), p, create_graph=True)
    return (grad.norm(dim=1) - 1.0).abs().mean()


def clamped_l1(pred: torch.Tensor, target: torch.Tensor, delta: float) -> torch.Tensor:
    """DeepSDF's clamped L1, mean |clamp(pred) - clamp(target)| (clamp to [-delta, delta]), without its
    dead zone: where pred has left the band and its clamp is not the target's, the term is
    |pred - clamp(target)|, which pulls pred back (DeepSDF's term is constant there, so one overshoot
    of every prediction past delta, as a first Adam step did on the airplane, stopped training for good).
    Where pred lies in the band, or past the same bound as the target, the value is DeepSDF's."""
    t, p = target.clamp(-delta, delta), pred.clamp(-delta, delta)
    dead = (p != pred) & (p != t)
    return torch.where(dead, (pred - t).abs(), (p - t).abs()).mean()


class NeuralSDF(NetSDFFamily):
    """cfg: architecture (_ARCH_KEYS), geometric_init, init_radius, lr, batch, delta, w_sdf, w_surface,
    surface_tol, w_eikonal, grad_clip, lr_schedule/lr_final_ratio/lr_warmup (train.Schedule), trace."""

    family = "neural_sdf"
    sample_kind = "sdf"

    def __init__(self, cfg: Mapping[str, Any], domain: float = BOX_HALF):
        super().__init__(cfg, domain)
        self.net = self._new_net()

    def _new_net(self) -> SDFNet:
        net = SDFNet(**{k: self.cfg[k] for k in _ARCH_KEYS}, half=self.domain)
        if bool(self.cfg["geometric_init"]):
            net.geometric_init(float(self.cfg["init_radius"]))
        return net.eval()

    def fit(self, data: FitData, budget: Budget, probe: Probe | None = None) -> FitStats:
        self.device = budget.device
        x, s = self._sdf_tensors(data)
        seed_everything(budget.seed)
        self.net = net = self._new_net().to(self.device)
        batch = min(int(self.cfg["batch"]), len(x))
        delta = float(self.cfg["delta"])
        w_sdf, w_surf, w_eik = (float(self.cfg[k]) for k in ("w_sdf", "w_surface", "w_eikonal"))
        surface_tol = float(self.cfg["surface_tol"])

        def step_fn(step: int) -> torch.Tensor:
            idx = torch.randint(0, len(x), (batch,), device=self.device)
            xb, sb = x[idx], s[idx]
            loss = x.new_zeros(())
            if w_sdf or w_surf:
                pred = net(xb)
                if w_sdf:
                    loss = loss + w_sdf * clamped_l1(pred, sb, delta)
                on_surface = sb.abs() <= surface_tol
                if w_surf and bool(on_surface.any()):
                    loss = loss + w_surf * pred[on_surface].abs().mean()
            if w_eik:
                uniform = (torch.rand_like(xb) * 2 - 1) * self.domain
                loss = loss + w_eik * eikonal_residual(net, uniform)
            return loss

        optimizer = torch.optim.Adam(net.parameters(), lr=float(self.cfg["lr"]))
        stats = self._train(net, optimizer, step_fn, budget, probe)
        stats.extra["n_params"] = self.n_params()
        return stats


FAMILY = NeuralSDF
