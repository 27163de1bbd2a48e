"""The one training loop shared by every learned family.

API (stable; families call only these):

    device = resolve_device("auto")            # "cpu" | "cuda" | "auto" -> "cpu" or "cuda"
    seed_everything(seed)                      # python, numpy and torch RNGs
    schedule = Schedule.from_cfg(cfg)          # lr decay over the budget (see Schedule)
    stats = train_loop(module, optimizer, step_fn, budget, schedule, probe_fn)

`step_fn(step) -> loss` draws its own batch, runs the forward pass and returns a
scalar loss tensor; the loop does zero_grad / backward / (optional clipping) /
optimizer.step. Training stops at `budget.max_steps` or after
`budget.max_seconds` of training wall clock, whichever comes first. Probes
(`probe_fn() -> dict` of cheap metrics, run with the module in eval mode) are
timed apart and do not count against the budget; they fire at `budget.n_probes`
log-spaced fractions of the budget (progress = max(step share, time share)),
the last one always at the end. The learning-rate schedule runs on that same
progress, so a wall-clock-limited run still decays to its final rate.

Checkpoints: with budget.checkpoint set, the loop saves its whole state every checkpoint.every_s
seconds of training and a fit given a saved state of itself goes on from it (ddfbench.fit.checkpoint).

NaN guard: a non-finite loss (checked every step) or non-finite weights
(checked every `weight_check_every` steps and at the end) stops the run;
FitStats.status is "failed" and FitStats.message names the step and the reason.
"""

from __future__ import annotations

import math
import random
import sys
import time
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np
import torch
from tqdm import tqdm

from ddfbench.core.clock import clock
from ddfbench.core.errors import InputError
from ddfbench.core.representation import Budget, FitStats
from ddfbench.fit.checkpoint import restore, rng_state, set_rng_state, state_of

_CURVE_POINTS = 256  # the loss curve keeps at most 2x this many (step, seconds, mean loss) rows


def resolve_device(name: str, option: str = "train.device") -> str:
    """'cpu' | 'cuda' | 'auto' -> the torch device string to use ('auto' picks cuda when available);
    `option` names the setting in the error message."""
    name = str(name).lower()
    if name == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cpu":
        return "cpu"
    if name.startswith("cuda"):
        if not torch.cuda.is_available():
            raise InputError(f"{option} '{name}': CUDA is not available on this machine (use cpu or auto)")
        return name
    raise InputError(f"{option} '{name}': unknown device (cpu | cuda | auto)")


def strict_fp32() -> None:
    """TF32 off for CUDA matrix products and cuDNN convolutions, so that a CUDA fit or render computes in
    the same float32 as a CPU one (PyTorch lets cuDNN convolutions, such as the GAN generator's Conv1d,
    run in TF32 by default, ~1e-3 relative). The bench sets its precisions itself (bench.timing)."""
    torch.backends.cuda.matmul.allow_tf32 = False
    torch.backends.cudnn.allow_tf32 = False


def seed_everything(seed: int) -> None:
    """Seed python, numpy and torch (all devices) so a fit is repeatable on one machine."""
    random.seed(int(seed))
    np.random.seed(int(seed) % (2**32))
    torch.manual_seed(int(seed))


@dataclass
class Schedule:
    """Learning-rate factor as a function of budget progress p in [0, 1].

    kind: "constant" | "cosine" (to final_ratio at p=1) | "exponential" (geometric to final_ratio).
    warmup: share of the budget with a linear ramp from 0.
    """

    kind: str = "constant"
    final_ratio: float = 0.01
    warmup: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in ("constant", "cosine", "exponential"):
            raise InputError(f"lr schedule '{self.kind}': unknown (constant | cosine | exponential)")
        if not 0.0 < self.final_ratio <= 1.0:
            raise InputError(f"lr final_ratio {self.final_ratio}: must be in (0, 1]")
        if not 0.0 <= self.warmup < 1.0:
            raise InputError(f"lr warmup {self.warmup}: must be in [0, 1)")

    @staticmethod
    def from_cfg(cfg: Mapping[str, Any]) -> "Schedule":
        """From keys lr_schedule, lr_final_ratio, lr_warmup of a model config (every learned family's YAML
        declares them)."""
        return Schedule(kind=str(cfg["lr_schedule"]), final_ratio=float(cfg["lr_final_ratio"]),
                        warmup=float(cfg["lr_warmup"]))

    def factor(self, progress: float) -> float:
        """The learning-rate multiplier at `progress` (fraction of the budget spent, clipped to [0, 1])."""
        p = min(max(progress, 0.0), 1.0)
        ramp = min(1.0, p / self.warmup) if self.warmup > 0 else 1.0
        if self.kind == "cosine":
            decay = self.final_ratio + (1 - self.final_ratio) * 0.5 * (1 + math.cos(math.pi * p))
        elif self.kind == "exponential":
            decay = self.final_ratio**p
        else:
            decay = 1.0
        return ramp * decay


def probe_fractions(n_probes: int) -> list[float]:
    """Log-spaced budget fractions ending at 1 (factor 3 apart): n=4 -> [1/27, 1/9, 1/3, 1]."""
    return [3.0 ** -(n_probes - 1 - i) for i in range(n_probes)] if n_probes > 0 else []


class _LossCurve:
    """Window-averaged (step, seconds, loss) rows; halves its resolution when it grows too long."""

    def __init__(self, max_rows: int = _CURVE_POINTS):
        self.rows: list[tuple[int, float, float]] = []
        self.window, self._sum, self._n, self.max_rows = 1, 0.0, 0, max_rows

    def add(self, step: int, seconds: float, loss: float) -> None:
        self._sum, self._n = self._sum + loss, self._n + 1
        if self._n >= self.window:
            self.rows.append((step, seconds, self._sum / self._n))
            self._sum, self._n = 0.0, 0
            if len(self.rows) >= 2 * self.max_rows:
                self.rows = self.rows[1::2]
                self.window *= 2

    def state(self) -> dict[str, Any]:
        return {"rows": list(self.rows), "window": self.window, "sum": self._sum, "n": self._n}

    def restore(self, state: Mapping[str, Any]) -> None:
        self.rows, self.window, self._sum, self._n = list(state["rows"]), state["window"], state["sum"], state["n"]

    def flush(self, step: int, seconds: float) -> None:
        if self._n:
            self.rows.append((step, seconds, self._sum / self._n))
            self._sum, self._n = 0.0, 0


def _first_nonfinite_param(module: torch.nn.Module) -> str | None:
    for name, p in module.named_parameters():
        if not bool(torch.isfinite(p).all()):
            return name
    return None


def train_loop(
    module: torch.nn.Module,
    optimizer: torch.optim.Optimizer,
    step_fn: Callable[[int], torch.Tensor],
    budget: Budget,
    schedule: Schedule | None = None,
    probe_fn: Callable[[], Mapping[str, float]] | None = None,
    grad_clip: float | None = None,
    weight_check_every: int = 50,
    desc: str = "fit",
    quiet: bool | None = None,
    state: Mapping[str, Any] | None = None,
) -> FitStats:
    """Train `module` with `optimizer` on losses from `step_fn` until the budget is spent.

    Returns FitStats: steps, seconds (training only), loss_curve [(step, seconds, mean loss)],
    probes [{"step", "seconds", **probe_fn()}], status "ok" | "failed" with message, and
    extra {device, stop ("max_steps" | "max_seconds" | "nonfinite"), final_lr, probe_seconds}, plus
    resumed_at (the steps it went on from) when budget.checkpoint held a saved state of this fit.
    quiet=None shows the tqdm bar only when stderr is a terminal. state: whatever else step_fn's
    result depends on that a checkpoint must keep, by name (another optimizer, a torch.Generator).
    """
    if budget.max_steps < 1 or budget.max_seconds <= 0:
        raise InputError(f"train budget max_steps={budget.max_steps}, max_seconds={budget.max_seconds}: both must be > 0")
    schedule = schedule or Schedule()
    base_lrs = [g["lr"] for g in optimizer.param_groups]
    stepped = [p for g in optimizer.param_groups for p in g["params"]]
    fractions = probe_fractions(int(budget.n_probes)) if probe_fn is not None else []
    stats = FitStats(extra={"device": budget.device})
    curve = _LossCurve()
    quiet = (not sys.stderr.isatty()) if quiet is None else quiet
    bar = tqdm(total=int(budget.max_steps), desc=desc, disable=quiet, leave=False, dynamic_ncols=True)

    # On CUDA the loss values come back to the host once per `weight_check_every` steps (one stacked copy),
    # and the clock is read, synchronized, at the same points: no per-step round trip. The budget and the
    # NaN guard then act at that granularity. The first step (cold: kernel choice, allocator) is a window
    # of its own, so the loss curve says what it cost and a warm rate can leave it out. On the CPU (no
    # queue to wait for) both happen every step.
    host_every = int(weight_check_every) if budget.device.startswith("cuda") else 1
    pending: list[torch.Tensor] = []
    train_s, probe_s, step, stop = 0.0, 0.0, 0, "max_steps"
    window_t0 = None
    saved = {"module": module, "optimizer": optimizer, **(state or {})}

    def save() -> None:
        ckpt.save({"fit": fit_label, "objects": state_of(saved), "rng": rng_state(budget.device), "step": step,
                   "train_s": train_s, "probe_s": probe_s, "fractions": fractions, "curve": curve.state(),
                   "probes": stats.probes, "resumed_at": stats.extra.get("resumed_at", [])})

    fit_label = (f"{desc} seed {budget.seed} max_steps {budget.max_steps} on {budget.device}, "
                 f"{torch.get_num_threads()} threads, torch {torch.__version__}")  # what a resume must match
    ckpt = budget.checkpoint
    resumed = ckpt.load(fit_label) if ckpt is not None else None
    if resumed is not None:
        restore(saved, resumed["objects"])
        set_rng_state(resumed["rng"])
        step, train_s, probe_s, fractions = resumed["step"], resumed["train_s"], resumed["probe_s"], resumed["fractions"]
        curve.restore(resumed["curve"])
        stats.probes = resumed["probes"]
        stats.extra["resumed_at"] = [*resumed["resumed_at"], step]
        bar.update(step)
    last_save = train_s
    module.train()
    while step < budget.max_steps:
        progress = max(step / budget.max_steps, train_s / budget.max_seconds)
        if progress >= 1.0:
            stop = "max_seconds"
            break
        factor = schedule.factor(progress)
        for g, lr in zip(optimizer.param_groups, base_lrs):
            g["lr"] = lr * factor

        window_t0 = clock() if window_t0 is None else window_t0
        optimizer.zero_grad(set_to_none=True)
        loss = step_fn(step)
        pending.append(loss.detach())
        if host_every == 1 and not math.isfinite(float(pending[-1])):
            stats.status, stats.message, stop = "failed", f"step {step}: loss is {float(pending[-1])} (non-finite)", "nonfinite"
            break
        loss.backward()
        if grad_clip:  # the gradient the optimizer steps with: module may hold others (the GAN's D, stepped apart)
            torch.nn.utils.clip_grad_norm_(stepped, float(grad_clip))
        optimizer.step()
        step += 1
        if step % weight_check_every == 0 and (bad := _first_nonfinite_param(module)) is not None:
            stats.status, stop = "failed", "nonfinite"
            stats.message = f"step {step}: weights '{bad}' became non-finite"
            break
        if step % host_every and step != 1 and step < budget.max_steps:
            continue
        train_s += clock() - window_t0  # after the queued CUDA work of the window
        window_t0 = None
        values = torch.stack(pending).float().tolist()
        pending.clear()
        first_bad = next((k for k, v in enumerate(values) if not math.isfinite(v)), None)
        if first_bad is not None:
            bad_step = step - len(values) + first_bad
            stats.status, stats.message, stop = "failed", f"step {bad_step}: loss is {values[first_bad]} (non-finite)", "nonfinite"
            break
        for k, value in enumerate(values):
            curve.add(step - len(values) + k + 1, train_s, value)
        bar.update(len(values))
        if step % 50 < len(values):
            bar.set_postfix(loss=f"{values[-1]:.4g}", s=f"{train_s:.0f}")

        progress = max(step / budget.max_steps, train_s / budget.max_seconds)
        while fractions and progress >= fractions[0] and progress < 1.0:
            fractions.pop(0)
            probe_s += _run_probe(module, probe_fn, stats, step, train_s)
        if ckpt is not None and train_s - last_save >= ckpt.every_s and step < budget.max_steps:
            last_save = train_s
            save()
    bar.close()

    if stats.status == "ok" and (bad := _first_nonfinite_param(module)) is not None:
        stats.status, stop = "failed", "nonfinite"
        stats.message = f"step {step}: weights '{bad}' became non-finite"
    curve.flush(step, train_s)
    if fractions and stats.status == "ok":
        probe_s += _run_probe(module, probe_fn, stats, step, train_s)
        fractions.clear()
    if ckpt is not None and stats.status == "ok":
        save()  # the finished fit: a run killed later (mesh, metrics) does not train again
    module.eval()
    stats.steps, stats.seconds, stats.loss_curve = step, train_s, curve.rows
    stats.extra.update(stop=stop, final_lr=float(optimizer.param_groups[0]["lr"]), probe_seconds=probe_s)
    return stats


def _run_probe(module, probe_fn, stats: FitStats, step: int, train_s: float) -> float:
    """Run one probe in eval mode, append it to stats.probes; return the seconds it took."""
    t0 = time.perf_counter()
    module.eval()
    try:
        result = dict(probe_fn())
    finally:
        module.train()
    stats.probes.append({"step": step, "seconds": train_s, **result})
    return time.perf_counter() - t0
