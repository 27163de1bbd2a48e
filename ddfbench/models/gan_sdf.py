"""GAN-SDF (Zeng 2018 thesis): a generator G(x) -> signed distance trained against a discriminator.

G: Linear(3->256) -> Conv1d(1,16,7) -> MaxPool1d(3,1) -> Tanh -> Conv1d(16,32,5) -> MaxPool1d(3,1)
   -> ReLU -> Linear(7744->1). D: the same on (x, y, z, sdf) with LeakyReLU(0.2) after the second
   stage and a sigmoid output (thesis Appendix B). Training runs the Conv1d modules; evaluation without
   autograd (tracing, meshing) runs G as matrix products (ddfbench.models._gan_gemm, the same function to
   float tolerance), eval_batch points per call: the rewrite is fastest at chunks that keep its buffers
   in the core's cache (reports/bench/field_cost; the SDF families otherwise pass 65,536 points).

Target scale: the thesis fits a bunny about 4 units long (its level-set grid spans 4.1 units,
Appendix C); ours lives in the unit cube. G is trained on targets L = target_scale * sdf and
`field` divides by target_scale, so sdf() answers in unit-cube units while the loss weights and the
0.1 of the near-surface term keep the thesis' scale. The input points are not scaled.

Generator loss (thesis Eq. 4.2), P = G(x), L = the scaled signed distance, D's output after its sigmoid:
  w_mse * mean (P - L)^2 + w_near * near-surface term + w_adv * adversarial term
near-surface term, `near_term`:
  "exp"     mean (e^{-P^2/0.1} - e^{-L^2/0.1})^2   (the exponent's sign survives in the text, the e does not)
  "literal" mean ((L^2 - P^2)/0.1)^2               (the text as printed, without the e)
adversarial term, `adversarial`:
  "least_squares"  mean (D(x, P) - 1)^2  (Eq. 4.2: PG the predictions of D, LG filled with 1.0)
  "logistic"       BCE(D(x, P), real)    (the non-saturating GAN loss; not the thesis)
Discriminator loss (not given in the thesis; the counterpart of the adversarial term):
  least_squares: mean (D(x, L) - 1)^2 + mean D(x, P)^2;  logistic: BCE(real) + BCE(fake).
Options that make it train reliably, all off in the thesis configuration:
  w_anchor       * mean |clamp(P, -0.1, 0.1) - clamp(L, -0.1, 0.1)|  (an L1 anchor, DeepSDF clamp)
  spectral_norm  spectral normalization of every D layer
  w_gp           R1 gradient penalty w_gp/2 * mean ||grad_(x,L) D(x, L)||^2 on real samples
Budget: `epochs` (passes over the samples) caps the optimizer steps at ceil(epochs * N / batch); the
train budget's max_seconds still applies (the record's stop reason says which ended the fit).
Only G is the artifact (what a user ships): {"header": JSON config, "state_dict"}, weights_only.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Mapping

import torch
import torch.nn.functional as F
from torch import nn

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import BOX_HALF
from ddfbench.core.representation import Budget, FitData, FitStats, Probe
from ddfbench.evaluate.trace import autograd_normals
from ddfbench.fit.train import seed_everything
from ddfbench.models import _gan_gemm as gan_gemm
from ddfbench.models._sdf_family import NetSDFFamily
from ddfbench.models._stride1_pool import Stride1MaxPool1d
from ddfbench.models.neural_sdf import clamped_l1

GRAD_BATCH = 128  # fewest points a call through the Conv1d modules: their forward is fastest at 64-256 a call,
                  # by the run (reports/bench/field_cost and its repeats, no grad; autograd passes not timed there)


class ConvField(nn.Module):
    """The thesis' network: in_dim -> Linear 256 -> two Conv1d/MaxPool stages -> Linear(7744 -> 1) -> (M,).

    Trained as torch's Conv1d modules (the pools' backward as _stride1_pool's, the same gradients); gan_gemm
    evaluates the generator's function without them.
    """

    def __init__(self, in_dim: int, first_act: nn.Module, second_act: nn.Module):
        super().__init__()
        self.lift = nn.Linear(in_dim, 256)
        self.conv1, self.conv2 = nn.Conv1d(1, 16, 7), nn.Conv1d(16, 32, 5)
        self.pool = Stride1MaxPool1d(3)  # nn.MaxPool1d(3, stride=1) with a faster backward, same gradients
        self.act1, self.act2 = first_act, second_act
        self.head = nn.Linear(32 * 242, 1)  # 256 -7+1 -3+1 = 248; 248 -5+1 -3+1 = 242

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.lift(x)[:, None, :]
        h = self.act1(self.pool(self.conv1(h)))
        h = self.act2(self.pool(self.conv2(h)))
        return self.head(h.flatten(1)).squeeze(1)


def generator() -> ConvField:
    return ConvField(3, nn.Tanh(), nn.ReLU())


def discriminator(spectral: bool) -> ConvField:
    """D on (x, y, z, sdf) with the thesis' Tanh / LeakyReLU(0.2); returns logits (sigmoid applied by the loss)."""
    d = ConvField(4, nn.Tanh(), nn.LeakyReLU(0.2))
    if spectral:
        for name in ("lift", "conv1", "conv2", "head"):
            setattr(d, name, nn.utils.parametrizations.spectral_norm(getattr(d, name)))
    return d


def adversarial_losses(kind: str) -> tuple:
    """(generator term g(logits_fake), discriminator loss d(logits_real, logits_fake)) of one reading."""
    if kind == "least_squares":
        return (lambda fake: (torch.sigmoid(fake) - 1).pow(2).mean(),
                lambda real, fake: (torch.sigmoid(real) - 1).pow(2).mean() + torch.sigmoid(fake).pow(2).mean())
    if kind == "logistic":
        bce = F.binary_cross_entropy_with_logits
        return (lambda fake: bce(fake, torch.ones_like(fake)),
                lambda real, fake: bce(real, torch.ones_like(real)) + bce(fake, torch.zeros_like(fake)))
    raise InputError(f"model.adversarial '{kind}': unknown (least_squares | logistic)")


def near_surface_term(pred: torch.Tensor, target: torch.Tensor, reading: str) -> torch.Tensor:
    """The thesis' near-surface term under one of its two readings (see module docstring): pred and target
    (B,) SDF values in the scaled target units (target_scale), a scalar out."""
    if reading == "exp":
        return (torch.exp(-pred**2 / 0.1) - torch.exp(-target**2 / 0.1)).pow(2).mean()
    if reading == "literal":
        return ((target**2 - pred**2) / 0.1).pow(2).mean()
    raise InputError(f"model.near_term '{reading}': unknown (exp | literal)")


class GanSDF(NetSDFFamily):
    """cfg: w_mse, w_near, near_term, w_adv, adversarial, target_scale, epochs, w_anchor, spectral_norm, w_gp,
    lr, lr_d, betas, batch, eval_batch (points a matrix-product call), grad_clip, lr_schedule/lr_final_ratio/lr_warmup, trace."""

    family = "gan_sdf"
    sample_kind = "sdf"

    def __init__(self, cfg: Mapping[str, Any], domain: float = BOX_HALF):
        super().__init__(cfg, domain)
        near_surface_term(torch.zeros(1), torch.zeros(1), str(self.cfg["near_term"]))  # validates
        adversarial_losses(str(self.cfg["adversarial"]))  # validates
        self.scale = float(self.cfg["target_scale"])
        self.eval_batch = int(self.cfg["eval_batch"])
        self.grad_batch = max(self.eval_batch, GRAD_BATCH)
        if self.scale <= 0 or self.eval_batch < 1:
            raise InputError(f"model.target_scale {self.scale} / eval_batch {self.eval_batch}: both must be > 0")
        self.net = generator().eval()
        self._gemm = gan_gemm.GemmGenerator()  # evaluates self.net without autograd; holds its buffers

    def field(self, points: torch.Tensor) -> torch.Tensor:
        """G in unit-cube units (M, 3) -> (M,). With autograd off (tracing, meshing) as matrix products,
        eval_batch points a call (ddfbench.models._gan_gemm: the same function to float tolerance); with it
        on (gradients of the field), through the Conv1d module, grad_batch points a call."""
        if not torch.is_grad_enabled():
            return self._gemm(self.net, points, self.eval_batch).div_(self.scale)
        parts = [self.net(points[s : s + self.grad_batch]) for s in range(0, len(points), self.grad_batch)]
        return (torch.cat(parts) if parts else points.new_zeros(0)) / self.scale

    def surface_normals(self, points: torch.Tensor):
        """Autograd normals, grad_batch points per backward pass; one evaluation and one backward per point."""
        parts = [autograd_normals(self.net, points[s : s + self.grad_batch]) for s in range(0, len(points), self.grad_batch)]
        if not parts:
            return points.new_zeros((0, 3)), points.new_zeros(0, dtype=torch.bool), 0, 0
        m = int(points.shape[0])
        return torch.cat([n for n, _ in parts]), torch.cat([v for _, v in parts]), m, m

    def fit(self, data: FitData, budget: Budget, probe: Probe | None = None) -> FitStats:
        cfg = self.cfg
        self.device = budget.device
        x, s = self._sdf_tensors(data)
        s = s * self.scale
        seed_everything(budget.seed)
        g = self.net = generator().to(self.device)
        d = discriminator(bool(cfg["spectral_norm"])).to(self.device)
        both = nn.ModuleDict({"G": g, "D": d})  # the NaN guard watches both networks
        batch = min(int(cfg["batch"]), len(x))
        epochs = cfg["epochs"]
        if epochs is not None:
            if float(epochs) <= 0:
                raise InputError(f"model.epochs {epochs}: must be > 0 (or null for the train budget alone)")
            budget = replace(budget, max_steps=min(budget.max_steps, math.ceil(float(epochs) * len(x) / batch)))
        w_mse, w_near, w_adv, w_anchor, w_gp = (float(cfg[k]) for k in ("w_mse", "w_near", "w_adv", "w_anchor", "w_gp"))
        reading = str(cfg["near_term"])
        g_adv, d_adv = adversarial_losses(str(cfg["adversarial"]))
        betas = tuple(float(b) for b in cfg["betas"])
        opt_g = torch.optim.Adam(g.parameters(), lr=float(cfg["lr"]), betas=betas)
        opt_d = torch.optim.Adam(d.parameters(), lr=float(cfg["lr_d"]), betas=betas)
        anchor_delta = 0.1 * self.scale  # DeepSDF's 0.1 in unit-cube units

        def step_fn(step: int) -> torch.Tensor:
            idx = torch.randint(0, len(x), (batch,), device=self.device)
            xb, sb = x[idx], s[idx]
            pred = g(xb)
            # discriminator step (its own optimizer); a non-finite D loss is returned to trip the guard
            opt_d.zero_grad(set_to_none=True)
            real_in = torch.cat([xb, sb[:, None]], 1).requires_grad_(w_gp > 0)
            real = d(real_in)
            d_loss = d_adv(real, d(torch.cat([xb, pred.detach()[:, None]], 1)))
            if w_gp > 0:
                (grad,) = torch.autograd.grad(real.sum(), real_in, create_graph=True)
                d_loss = d_loss + 0.5 * w_gp * grad.pow(2).sum(1).mean()
            if not bool(torch.isfinite(d_loss)):
                return d_loss
            d_loss.backward()
            opt_d.step()
            # generator loss (the shared loop runs its backward and step)
            loss = w_mse * F.mse_loss(pred, sb) + w_near * near_surface_term(pred, sb, reading)
            if w_adv:
                loss = loss + w_adv * g_adv(d(torch.cat([xb, pred[:, None]], 1)))
            if w_anchor:
                loss = loss + w_anchor * clamped_l1(pred, sb, anchor_delta)
            return loss

        stats = self._train(both, opt_g, step_fn, budget, probe, state={"optimizer_d": opt_d})
        stats.extra.update(n_params=self.n_params(), epochs=stats.steps * batch / len(x))
        return stats


FAMILY = GanSDF
