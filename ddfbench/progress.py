"""Sweep progress: one line per finished job of a multirun, whatever the launcher.

  [12/32] ddf bunny ok  chamfer 0.345e-3  fit 60 s  elapsed 8:10  eta 13:40

The basic launcher ends jobs in the main process, joblib in worker processes and submitit on other
machines, so the callback keeps no state in memory: at the start of the sweep the main process
writes the job count and start time into <sweep dir>/.progress/sweep.json, and each finished job
claims the next number by creating <sweep dir>/.progress/<n> exclusively (atomic on one file
system), so two jobs ending at once never print the same count. A job whose ok record was already
there (a resumed sweep) counts as done and says `skipped`. Plain lines, flushed: a CI log gets them
as they happen and nothing redrawn.
"""

from __future__ import annotations

import json
import os
import time
from typing import Any

from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.utils import JobStatus
from hydra.experimental.callback import Callback
from hydra.types import RunMode
from omegaconf import DictConfig

PROGRESS_DIR = ".progress"


def sweep_size(sweeper_params: dict[str, Any], command_line: list[str]) -> int:
    """Jobs in a basic-sweeper grid: the product of the sweep lengths, the command line winning per key."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper

    overrides = [f"{k}={v}" for k, v in sweeper_params.items()] + list(command_line)
    batches = BasicSweeper.split_arguments(OverridesParser.create().parse_overrides(overrides), None)
    return len(batches[0])


def clock(seconds: float) -> str:
    """7.9 → 0:08, 490 → 8:10, 3725 → 1:02:05."""
    s = int(round(max(seconds, 0.0)))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


def claim_number(folder: str) -> int:
    """The next free n ≥ 1 whose file folder/n this call created (exclusive create: unique under races)."""
    n = len([f for f in os.listdir(folder) if f.isdigit()]) + 1
    while True:
        try:
            os.close(os.open(os.path.join(folder, str(n)), os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            return n
        except FileExistsError:
            n += 1


def job_summary(record: dict[str, Any] | None, sweep_started: float) -> str:
    """'ddf bunny ok  chamfer 0.345e-3  fit 60 s' (or '... failed  <error>', '... skipped  ...')."""
    if record is None:
        return "no record"
    label = f"{record.get('model')} {(record.get('shape') or {}).get('name')}"
    if record.get("status") != "ok":
        return f"{label} failed  {str(record.get('error') or '')[:100]}"
    finished = record.get("finished")
    skipped = bool(finished) and _epoch(finished) < sweep_started - 1.0
    parts = [f"{label} {'skipped' if skipped else 'ok'}"]
    metrics = record.get("metrics") or {}
    chamfer = metrics.get("chamfer_l2")
    if metrics.get("empty_reconstruction"):
        parts.append("chamfer penalty (empty mesh)")
    elif isinstance(chamfer, (int, float)):
        parts.append(f"chamfer {chamfer * 1e3:.3g}e-3" if chamfer < 1 else f"chamfer {chamfer:.3g}")
    fit = (record.get("cost") or {}).get("fit_s")
    if isinstance(fit, (int, float)):
        parts.append(f"fit {fit:.0f} s" if fit >= 10 else f"fit {fit:.1f} s")
    return "  ".join(parts)


def _epoch(iso: str) -> float:
    import datetime as _dt

    return _dt.datetime.fromisoformat(iso).timestamp()


def progress_line(done: int, total: int, summary: str, elapsed_s: float) -> str:
    """'[done/total] summary  elapsed m:ss  eta m:ss' (eta from the mean time per finished job so far)."""
    eta = elapsed_s / done * max(total - done, 0) if done else 0.0
    return f"[{done}/{total}] {summary}  elapsed {clock(elapsed_s)}  eta {clock(eta)}"


def _read_record(config: DictConfig, key: Any) -> dict[str, Any] | None:
    from ddfbench.runs import read_record

    if not isinstance(key, str):
        return None
    return read_record(os.path.join(str(config.get("out_dir", "results")), str(config.experiment_name), key,
                                    "record.json"))


class SweepProgressCallback(Callback):
    """Hydra callback (conf/config.yaml hydra.callbacks): the per-job progress lines of a multirun."""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        folder = os.path.join(str(config.hydra.sweep.dir), PROGRESS_DIR)
        os.makedirs(folder, exist_ok=True)
        total = sweep_size(dict(config.hydra.sweeper.get("params") or {}), list(config.hydra.overrides.task))
        with open(os.path.join(folder, "sweep.json"), "w") as fh:
            json.dump({"total": total, "started": time.time()}, fh)

    def on_job_end(self, config: DictConfig, job_return: Any, **kwargs: Any) -> None:
        if config.hydra.mode != RunMode.MULTIRUN:
            return
        folder = os.path.join(str(config.hydra.sweep.dir), PROGRESS_DIR)
        try:
            with open(os.path.join(folder, "sweep.json")) as fh:
                sweep = json.load(fh)
        except (OSError, ValueError):
            return  # a sweeper or launcher that skipped on_multirun_start: no line rather than a wrong one
        done = claim_number(folder)
        if job_return.status == JobStatus.FAILED:  # the task raised (runner.run itself never does)
            exc = job_return._return_value
            summary = f"job #{config.hydra.job.num} failed  {type(exc).__name__}: {str(exc).strip()[:100]}"
        else:
            summary = job_summary(_read_record(config, job_return.return_value), float(sweep["started"]))
        print(progress_line(done, int(sweep["total"]), summary, time.time() - float(sweep["started"])), flush=True)
