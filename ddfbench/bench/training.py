"""Section 7, training throughput: samples/s of each learned family's fit at its default preset,
against a bare training step of the same network on the same batch size (forward, L1 loss, backward,
Adam), measured in the same process. The ratio is what the family's loss terms (visibility head,
eikonal double backward, discriminator) and the shared training loop keep of the bare step's speed.

Data: surface samples of the family's kind from the conf/sampling/surface.yaml preset. The fit runs
`steps` steps; its warm rate leaves out the first (cold) step, read off the loss curve.
Families: every registered family that is learned (a family whose fit fails gets a note).
Sizes: shape, steps, overrides {family: {model keys}}.
"""

from __future__ import annotations

import numpy as np
import torch

from ddfbench.bench.context import Context, model_preset, preset
from ddfbench.bench.results import Row, SectionResult, compare
from ddfbench.bench.timing import measure, once, precisions
from ddfbench.core.errors import one_line
from ddfbench.core.representation import Budget, FitData
from ddfbench.models import learned_families, load_family
from ddfbench.sampling import line_hits, surface


def batch_size(rep, stats) -> int:
    """Samples per step: the fit's own report, else the family's `batch` key (one spelling in every family)."""
    return int(stats.extra.get("batch_size") or rep.cfg["batch"])


def warm_rate(stats, batch: int) -> float:
    """Samples per training second after the first step (loss curve rows are (step, seconds, loss))."""
    first = next((sec for step, sec, _ in stats.loss_curve if step >= 1), 0.0)
    steps = stats.steps - 1 if stats.steps > 1 else stats.steps
    seconds = stats.seconds - first if stats.steps > 1 else stats.seconds
    return steps * batch / seconds


def bare_step_fn(net: torch.nn.Module, kind: str, samples, batch: int, device: str):
    """One forward + L1 loss + backward + Adam step of `net` on a fixed batch of the samples."""
    x = torch.as_tensor(samples.x[:batch], device=device)
    if kind == "rays":
        d = torch.as_tensor(samples.d[:batch], device=device)
        target = torch.as_tensor(np.nan_to_num(samples.t[:batch], posinf=0.0), device=device)
        forward = lambda: net(x, d)[0]  # noqa: E731
    else:
        target = torch.as_tensor(samples.sdf[:batch], device=device)
        forward = lambda: net(x)  # noqa: E731
    opt = torch.optim.Adam(net.parameters(), lr=1e-6)
    net.train()

    def step() -> None:
        opt.zero_grad(set_to_none=True)
        (forward().reshape(-1) - target).abs().mean().backward()
        opt.step()

    return step


def family_rows(ctx: Context, family: str, samples_by_kind: dict, details: dict) -> list[Row]:
    """Fit `family` for `steps` steps per precision and time a bare step of its network beside it."""
    s = ctx.sizes
    shape, oracle = ctx.shape(s["shape"]), ctx.oracle(s["shape"])
    Family = load_family(family)
    kind = Family.sample_kind or "rays"
    if kind not in samples_by_kind:
        got = surface.sample(shape, oracle, preset("sampling", "surface"), kind, np.random.default_rng(0))[0]
        if kind == "rays":  # as sampling.build gives them to a run
            got.line_hit = line_hits(oracle, got.x, got.d, got.hit)
        samples_by_kind[kind] = got
    samples, rows = samples_by_kind[kind], []
    for prec in (p for p in precisions(ctx.device) if p != "bf16"):  # no family trains in bf16
        kw = dict(device=ctx.device, precision=prec)
        rep = Family(model_preset(family, **dict((s.get("overrides") or {}).get(family) or {})))
        budget = Budget(max_steps=int(s["steps"]), max_seconds=1e9, device=ctx.device, n_probes=0)
        stats, fit_t = once(lambda: rep.fit(FitData(samples, shape.mesh, oracle), budget), **kw)
        batch = batch_size(rep, stats)
        _, bare_t = measure(bare_step_fn(rep.net, kind, samples, batch, ctx.device), ctx.repeats, ctx.warmup, **kw)
        details[f"{family}_{prec}"] = {"steps": stats.steps, "fit_seconds": stats.seconds, "fit_wall": fit_t.as_dict(),
                                       "batch": batch, "samples": len(samples), "n_params": rep.n_params(),
                                       "status": stats.status, "bare_step": bare_t.as_dict()}
        rows.append(compare(
            "training", f"{family}: training samples/s (batch {batch}, {stats.steps} steps)", warm_rate(stats, batch),
            "samples/s", "bare forward + L1 + backward + Adam step of the same network, samples/s", bare_t.rate(batch),
            threads=ctx.threads, **kw))
    return rows


def run(ctx: Context) -> SectionResult:
    result, samples_by_kind = SectionResult(), {}
    for family in learned_families():
        try:
            result.rows += family_rows(ctx, family, samples_by_kind, result.details)
        except Exception as err:  # one family's failure leaves the others' figures standing
            result.notes.append(f"{family}: failed, {one_line(err)}")
    if not result.rows:
        raise RuntimeError("no family was measured: " + "; ".join(result.notes))
    return result
