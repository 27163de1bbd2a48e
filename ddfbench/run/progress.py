"""Sweep progress: one line per finished job, whatever the launcher.

    [12/32] ddf bunny ok  chamfer 0.35e-3  fit 60 s  elapsed 8:10  eta 13:40

`start_sweep` runs once in the launching process (Hydra's on_multirun_start) and writes the job
count and start time into the sweep folder; `job_finished` runs in whichever process ran the job
(the launcher's own for the basic launcher, a worker for joblib) and takes the next count under a
file lock, so parallel workers never print the same number. Skipped runs (an ok record existed)
count as done.
"""

from __future__ import annotations

import fcntl
import json
import math
import os
import time
from typing import Any, Mapping

STATE_FILE = "progress.json"
COUNT_FILE = "progress.count"


def count_jobs(overrides: list[str], sweeper_params: Mapping[str, Any] | None, n_trials: int | None = None) -> int:
    """How many jobs a sweep launches: the product of its sweep lists (the basic sweeper's rule), or
    n_trials for a sweeper that samples trials (Optuna)."""
    if n_trials:
        return int(n_trials)
    from hydra.core.override_parser.overrides_parser import OverridesParser

    args = [f"{k}={v}" for k, v in (sweeper_params or {}).items()] + list(overrides)
    sizes: dict[str, int] = {}
    for o in OverridesParser.create().parse_overrides(args):
        sizes[o.get_key_element()] = len(list(o.sweep_string_iterator())) if o.is_discrete_sweep() else 1
    return math.prod(sizes.values())


def start_sweep(sweep_dir: str, total: int) -> None:
    """Record the job count and the start time of a sweep in its folder."""
    os.makedirs(sweep_dir, exist_ok=True)
    with open(os.path.join(sweep_dir, STATE_FILE), "w") as fh:
        json.dump({"total": int(total), "started": time.time()}, fh)
    with open(os.path.join(sweep_dir, COUNT_FILE), "w") as fh:
        fh.write("0")


def sweep_total(sweep_dir: str) -> int | None:
    """The job count start_sweep recorded for the sweep (None where it has no readable state)."""
    try:
        with open(os.path.join(sweep_dir, STATE_FILE)) as fh:
            return int(json.load(fh)["total"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _next_count(sweep_dir: str) -> int:
    """Increment the sweep's finished-job counter under an exclusive lock; return the new value."""
    with open(os.path.join(sweep_dir, COUNT_FILE), "r+") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        done = int(fh.read().strip() or 0) + 1
        fh.seek(0)
        fh.truncate()
        fh.write(str(done))
        fh.flush()
        return done


def clock(seconds: float) -> str:
    """h:mm:ss or m:ss."""
    s = int(round(max(seconds, 0.0)))
    h, rest = divmod(s, 3600)
    return f"{h}:{rest // 60:02d}:{rest % 60:02d}" if h else f"{rest // 60}:{rest % 60:02d}"


def line(done: int, total: int, record: Mapping[str, Any], elapsed: float) -> str:
    """The progress line of one finished job."""
    shape = (record.get("shape") or {}).get("name", "?")
    parts = [f"[{done}/{total}] {record.get('model', record.get('family', '?'))} {shape} {record.get('status', '?')}"]
    chamfer = (record.get("metrics") or {}).get("chamfer_l2")
    if "empty_reconstruction" in (record.get("flags") or []):
        parts.append("chamfer penalty (empty mesh)")
    elif isinstance(chamfer, (int, float)):
        parts.append(f"chamfer {chamfer * 1e3:.3g}e-3" if chamfer < 1 else f"chamfer {chamfer:.3g}")
    if "non_watertight_input" in (record.get("flags") or []):  # the family's signs came from an inside test
        parts.append("(open input mesh: inside/outside labels unreliable)")
    fit_s = (record.get("cost") or {}).get("fit_s")
    if isinstance(fit_s, (int, float)):
        parts.append(f"fit {fit_s:.3g} s")
    if record.get("status") != "ok" and record.get("error"):
        parts.append(str(record["error"]))
    parts.append(f"elapsed {clock(elapsed)}")
    if done < total:
        parts.append(f"eta {clock(elapsed / done * (total - done))}")
    return "  ".join(parts)


def job_finished(sweep_dir: str, record: Mapping[str, Any]) -> str | None:
    """Count the job as done and return its progress line (None where the sweep has no state)."""
    state_path = os.path.join(sweep_dir, STATE_FILE)
    if not os.path.exists(state_path):
        return None
    with open(state_path) as fh:
        state = json.load(fh)
    done = _next_count(sweep_dir)
    return line(done, max(int(state["total"]), done), record, time.time() - float(state["started"]))
