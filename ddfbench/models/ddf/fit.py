"""Training the DDF: its labels (the samples' rays, plus exact visibility labels where their lines enter
the box) and the fit loop (l1 on hits with a visibility head's cross entropy, or the paper's clamp loss over all
samples: clamp_loss).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import box_entry
from ddfbench.core.representation import Budget, FitData, FitStats, Probe, Representation
from ddfbench.fit.budget import entry_per_batch
from ddfbench.fit.train import Schedule, seed_everything, train_loop
from ddfbench.models.ddf.network import DDFNet

MAX_ENTRY_LINES = 1 << 22  # sample lines drawn (seeded) for the entry labels: 4M lines, 100 MB


def clamp_loss(pred: torch.Tensor, t: torch.Tensor, hit: torch.Tensor, delta: float, mode: str) -> torch.Tensor:
    """The paper's Eq. 8 per sample, |clamp(y, delta) - clamp(y_hat, delta)|, misses labelled delta; pred, t,
    hit (N,), distances in unit-cube units. mode "clamp": as printed, so a prediction beyond delta gets no
    gradient whatever its label; "clamp_misses": the prediction is clamped only where the label is delta
    (misses, far hits), so a near hit predicted beyond delta is still pulled back.

    Both clamp from above only, min(., delta): the paper's clamp(x, delta) = min(delta, max(-delta, x)) also
    floors at -delta, where a prediction below -delta gets no gradient; here it gets the full one (labels are
    >= 0, so only predictions below -delta differ)."""
    target = torch.where(hit, t.clamp(max=delta), delta)
    clamped = pred.clamp(max=delta)
    if mode == "clamp_misses":
        clamped = torch.where(hit & (t < delta), pred, clamped)
    return (clamped - target).abs()


def line_entry_labels(x: np.ndarray, d: np.ndarray, line_hit: np.ndarray, half: float,
                      rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact visibility labels where sample lines enter the box [-half, half]^3, the queries intersect
    and to_mesh make: the samples' rows (M,) of x (N,3), unit d (N,3) and line_hit (N,) bool (whether
    the whole line meets the surface, Samples.line_hit), moved back along -d to the box boundary.
    Returns (entry points (M,3) float32, directions (M,3) float32, hit (M,) bool).
    """
    xs, ds = np.asarray(x[rows], np.float32), np.asarray(d[rows], np.float32)
    back = box_entry(xs, -ds, half)[1]
    return xs - back[:, None] * ds, ds, np.asarray(line_hit[rows], bool)


def fit(rep: Representation, data: FitData, budget: Budget, probe: Probe | None = None) -> FitStats:
    """Train rep.net (a fresh DDFNet on budget.device) on ray samples; see the module docstring."""
    s = data.samples
    if s is None or s.d is None or s.t is None or s.hit is None:
        raise InputError("model ddf: needs ray samples (x, d, t, hit); the sampler gave none")
    if len(s) == 0:
        raise InputError("model ddf: the sample set is empty")
    seed_everything(budget.seed)
    rep.device = budget.device
    rep.net = DDFNet(rep.cfg, rep.domain).to(rep.device)
    dev = rep.device
    x = torch.as_tensor(s.x, dtype=torch.float32, device=dev)
    d = torch.as_tensor(s.d, dtype=torch.float32, device=dev)
    hit = torch.as_tensor(s.hit, dtype=torch.bool, device=dev)
    t = torch.where(hit, torch.as_tensor(np.nan_to_num(s.t, posinf=0.0), dtype=torch.float32, device=dev), 0.0)
    cfg, n = rep.cfg, len(s)
    gen = torch.Generator(device=dev).manual_seed(int(budget.seed))
    delta = float(cfg["delta"])
    lines = np.zeros(0, np.int64) if s.line_hit is None else \
        np.random.default_rng(int(budget.seed)).choice(n, min(n, MAX_ENTRY_LINES), replace=False)
    line_hit = s.hit if s.line_hit is None else s.line_hit  # no line labels: no rows either
    xe, de, he = (torch.as_tensor(a, device=dev) for a in line_entry_labels(s.x, s.d, line_hit, rep.domain, lines))
    n_hit_entries = int(he.sum())
    both = 0 < n_hit_entries < len(he)  # one class alone would only bias the head: then none
    n_entry = entry_per_batch(cfg) if both else 0  # as fit.budget counts an epoch's steps
    n_main = int(cfg["batch"]) - n_entry
    order = torch.argsort((~he).to(torch.uint8), stable=True)  # entry hits first, then misses
    xe, de, he = xe[order], de[order], he[order]

    def step_fn(step: int) -> torch.Tensor:
        i = torch.randint(0, n, (n_main,), device=dev, generator=gen)
        half = n_entry // 2  # as many entry hits as entry misses
        j = torch.cat([torch.randint(0, max(n_hit_entries, 1), (half,), device=dev, generator=gen),
                       torch.randint(n_hit_entries, max(len(he), n_hit_entries + 1), (half,), device=dev, generator=gen)])
        pred, logit = rep.net(torch.cat([x[i], xe[j]]), torch.cat([d[i], de[j]]))
        pred, h = pred[:n_main], hit[i]
        if cfg["loss"] != "l1":
            dist_loss = clamp_loss(pred, t[i], h, delta, cfg["loss"])
            dist_loss = dist_loss.mean() if logit is None else dist_loss[h].sum() / h.sum().clamp_min(1)
        else:
            dist_loss = (pred - t[i]).abs()[h].sum() / h.sum().clamp_min(1)
        if logit is None:
            return dist_loss
        vis = nn.functional.binary_cross_entropy_with_logits(logit, torch.cat([h, he[j]]).float())
        return dist_loss + float(cfg["vis_weight"]) * vis

    optimizer = torch.optim.Adam(rep.net.parameters(), lr=float(cfg["lr"]), weight_decay=float(cfg["weight_decay"]))
    stats = train_loop(
        rep.net, optimizer, step_fn, budget, Schedule.from_cfg(cfg),
        probe_fn=(lambda: probe(rep)) if probe is not None else None,
        grad_clip=float(cfg["grad_clip"]) or None, desc="ddf", state={"batches": gen},
    )
    stats.extra.update(n_samples=n, hit_share=float(s.hit.mean()), n_params=rep.n_params(),  # the entry
                       entry_labels=len(he) if n_entry else 0, entry_hits=n_hit_entries if n_entry else 0,
                       entry_per_batch=n_entry)  # visibility labels it trained on (0: none)
    return stats
