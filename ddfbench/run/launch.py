"""What a Hydra launcher gives one job: its torch threads and its compute device.

Launchers (joblib, submitit, Ray) run many jobs side by side. A job reads its share of the machine
from the launcher's own config (`hydra.launcher`) and from what the scheduler exposes: the CPU
affinity mask (SLURM binds a task's cores) and CUDA_VISIBLE_DEVICES (SLURM, Ray and submitit's
local executor set it per task). Everything here is a function of its arguments; nothing is kept
from one job to the next in a reused worker process.
"""

from __future__ import annotations

import os
from typing import Any, Mapping

from ddfbench.core.errors import checked_int


def available_cores() -> int:
    """Cores this process may run on (the affinity mask where the OS has one, else all)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # macOS, Windows
        return os.cpu_count() or 1


def _get(cfg: Mapping[str, Any] | None, dotted: str) -> Any:
    """cfg["a"]["b"] for "a.b", or None where a level is missing or not a mapping."""
    for part in dotted.split("."):
        if not hasattr(cfg, "get"):
            return None
        cfg = cfg.get(part)  # type: ignore[union-attr]
    return cfg


def job_threads(threads: int, launcher: Mapping[str, Any] | None, cores: int) -> int:
    """Torch threads for one job, so that concurrent jobs × threads = cores.

    threads > 0 is taken as given. Otherwise (threads = 0, "auto") the launcher decides:
    submitit `cpus_per_task` or Ray `ray.remote.num_cpus` (the cores reserved for the task);
    joblib `n_jobs` (cores // n_jobs; n_jobs = -1 means one job per core, -2 all but one, ...);
    any other launcher runs one job at a time and gets every core.
    """
    if threads and int(threads) > 0:
        return int(threads)
    cores = max(1, int(cores))
    reserved = _get(launcher, "cpus_per_task") or _get(launcher, "ray.remote.num_cpus")
    if reserved:
        return max(1, min(int(reserved), cores))
    n_jobs = _get(launcher, "n_jobs")
    if n_jobs:
        concurrent = int(n_jobs) if int(n_jobs) > 0 else cores + 1 + int(n_jobs)
        return max(1, cores // max(1, concurrent))
    return cores


def job_device(requested: str, job_num: int, n_gpus: int) -> str:
    """The device for job `job_num` given train.device and the n_gpus this process can see.

    "cpu" and an explicit "cuda:K" are kept. "auto" is cpu without a visible GPU. "auto" and
    "cuda" with GPUs visible spread jobs over them: cuda:<job_num mod n_gpus>; under SLURM or Ray
    each task sees only its own GPU, so that is cuda:0. "cuda" without a GPU is left for the
    runner to reject with a clear message.
    """
    name = str(requested).lower()
    if name in ("auto", "cuda") and n_gpus > 0:
        return f"cuda:{int(job_num) % n_gpus}"
    if name == "auto":
        return "cpu"
    return name


def job_settings(cfg: Mapping[str, Any], hydra_cfg: Any) -> tuple[int, str]:
    """(threads, device) for the current Hydra job from its config and HydraConfig.get()."""
    import torch

    launcher = _get(hydra_cfg, "launcher")
    num = _get(hydra_cfg, "job.num")  # None outside a sweep
    raw = cfg.get("threads") or 0
    raw = int(raw) if isinstance(raw, str) and raw.strip().isdigit() else raw  # ${oc.env:...} gives a string
    threads = job_threads(checked_int(raw, "threads", 0), launcher, available_cores())
    device = job_device(str(_get(cfg, "train.device") or "cpu"), int(num or 0), torch.cuda.device_count())
    return threads, device
