"""What bounds a fit: a fixed amount of work (optimizer steps or epochs) or a wall-clock time.

`train.budget` (conf/train/default.yaml) picks one:
  steps       train.max_steps optimizer steps (null: the model's fit_steps); no time limit. Repeatable: the
              same steps on any machine.
  epochs      train.max_epochs passes over the labels: ceil(epochs x n_labels / sample_batch) steps, from
              the model config's `batch` (below); no time limit.
  wall-clock  train.max_seconds of training (or max_steps if set, whichever ends first): "what do I get in N
              seconds" runs. The steps taken vary with the machine and its load, so such records are
              labelled "wall-clock" in the record (fit.budget) and in every table.
The record's fit.budget is the bound that ended the fit, fit.epochs steps x sample_batch / labels (draws, as below).

An epoch counts draws, not distinct labels: every family draws its batches with replacement (torch.randint), so
one epoch shows about 1 - 1/e = 63 % of the labels at least once (40 epochs: all of them). An epoch counts the draws
from the sample set alone (sample_batch): the DDF with a visibility head fills entry_per_batch of its `batch` with
entry labels (ddfbench.models.ddf.fit.line_entry_labels) that the label count leaves out, so its epoch takes
ceil(epochs x labels / (batch - entry labels)) steps (before 1.7.0, labels / batch: reports/ablation's "1 epoch"
was 0.750 passes over its ray samples, 7,915 steps where a pass takes ~10,550).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

from ddfbench.core.errors import InputError

KINDS = ("steps", "epochs", "wall-clock")
NO_STEP_CAP = 10**12  # wall-clock and epochs with train.max_steps null: the time or the epochs end the fit


@dataclass(frozen=True)
class FitLimit:
    """kind: one of KINDS; max_steps >= 1; max_seconds > 0 (inf for a work budget)."""

    kind: str
    max_steps: int
    max_seconds: float


def entry_per_batch(model_cfg: Mapping[str, Any]) -> int:
    """Entry labels in each batch of a model with a visibility head (an even count: as many hits as misses, from
    `entry_share` of `batch`); 0 for every other model. The DDF's fit draws none where its lines give one class
    alone (then it draws `batch` samples a step)."""
    if model_cfg.get("visibility") != "head" or model_cfg.get("batch") is None:
        return 0
    return 2 * int(round(float(model_cfg.get("entry_share") or 0.0) * int(model_cfg["batch"]) / 2))


def sample_batch(model_cfg: Mapping[str, Any]) -> int | None:
    """Labels of the sample set one optimizer step draws: the model's `batch` less its entry labels
    (entry_per_batch); None when the model declares no batch (no batched fit)."""
    if model_cfg.get("batch") is None:
        return None
    return int(model_cfg["batch"]) - entry_per_batch(model_cfg)


def fit_limit(train_cfg: Mapping[str, Any], model_cfg: Mapping[str, Any], n_labels: int | None) -> FitLimit:
    """The limit a fit runs under, from the train config (see the module docstring)."""
    kind = str(train_cfg["budget"])
    if kind not in KINDS:
        raise InputError(f"train.budget '{kind}': unknown (steps | epochs | wall-clock)")
    cap = train_cfg["max_steps"]
    if kind == "steps":
        if cap is None:  # the model's own fixed work; a family that does not train (mesh, grid SDF) declares none
            cap = model_cfg["fit_steps"] if model_cfg.get("fit_steps") is not None else 1
        return FitLimit(kind, int(cap), math.inf)
    cap = NO_STEP_CAP if cap is None else int(cap)
    if kind == "wall-clock":
        return FitLimit(kind, cap, float(train_cfg["max_seconds"]))
    epochs = train_cfg.get("max_epochs")
    if epochs is None or float(epochs) <= 0:
        raise InputError(f"train.max_epochs {epochs!r}: train.budget=epochs needs a number > 0")
    batch = sample_batch(model_cfg)
    if batch is None or not n_labels:
        # families without a batched fit (mesh, grid SDF) build once; the limit does not bind them
        return FitLimit(kind, cap, math.inf)
    return FitLimit(kind, max(1, math.ceil(float(epochs) * int(n_labels) / batch)), math.inf)


def fit_record(limit: FitLimit, stop: str | None, steps: int, model_cfg: Mapping[str, Any],
               n_labels: int | None, entry_drawn: int | None = None) -> dict[str, Any]:
    """{budget, epochs} for the record's `fit`: budget is "wall-clock" when the time limit ended the fit,
    else the configured kind; epochs = steps x sample_batch / labels (None without a batch or labels).
    entry_drawn: the entry labels a step of the fit drew where it says (the DDF's fit.entry_per_batch: 0 where its
    lines gave one class alone, and then its steps drew the whole batch, more passes than the limit planned)."""
    batch = sample_batch(model_cfg)
    if batch is not None and entry_drawn is not None:
        batch = int(model_cfg["batch"]) - int(entry_drawn)
    return {
        "budget": "wall-clock" if stop == "max_seconds" else limit.kind,
        "epochs": steps * batch / n_labels if batch and n_labels else None,
    }
