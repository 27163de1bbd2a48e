"""Timing for the benchmark: cold vs warm, CUDA-synchronized, side by side, with the device,
precision and threads of every figure.

`measure_side_by_side({name: fn})` calls each fn once cold (lazy setup included: BVH commit, weights
to the device, kernel selection), then `warmup` untimed rounds, then `repeats` timed rounds; a round
calls every fn once (the order rotates from round to round), so a figure and its reference see the
same machine load. The warm figure is the
median and interquartile range of a fn's timed calls. Clock reads wait for queued CUDA work
(ddfbench.core.clock.clock), so asynchronous kernels are counted.
"""

from __future__ import annotations

import contextlib
from dataclasses import asdict, dataclass
from typing import Any, Callable, Iterator, TypeVar

import torch

from ddfbench.core.clock import median_iqr, timed

T = TypeVar("T")


@dataclass
class Timing:
    """Seconds: cold (the first call), warm median and IQR, every warm call in order; where and how measured."""

    cold_s: float
    median_s: float
    iqr_s: float
    runs_s: list[float]
    device: str
    precision: str
    threads: int

    def rate(self, count: float) -> float:
        """count per warm second (count / median)."""
        return float(count) / self.median_s

    def as_dict(self) -> dict:
        return asdict(self)


def measure_side_by_side(fns: dict[str, Callable[[], Any]], repeats: int, warmup: int = 1, device: str = "cpu",
                         precision: str = "fp32") -> dict[str, tuple[Any, Timing]]:
    """Cold call of each fn in order, `warmup` untimed rounds, `repeats` timed rounds (each fn once per
    round, the order rotated by one each round), all under `precision` (see precision_context).
    Returns {name: (its cold call's result, Timing)}."""
    cold: dict[str, tuple[Any, float]] = {}
    warm: dict[str, list[float]] = {name: [] for name in fns}
    names = list(fns)
    with precision_context(precision, device):
        for name in names:
            cold[name] = timed(fns[name])
        for r in range(max(0, int(warmup)) + max(1, int(repeats))):
            counted = r >= max(0, int(warmup))
            for name in names[r % len(names):] + names[:r % len(names)]:  # rotate: no fn always goes first
                seconds = timed(fns[name])[1]
                if counted:
                    warm[name].append(seconds)
    out = {}
    for name, runs in warm.items():
        out[name] = (cold[name][0], Timing(cold[name][1], *median_iqr(runs), runs, device, precision,
                                           torch.get_num_threads()))
    return out


def measure(fn: Callable[[], T], repeats: int, warmup: int = 1, device: str = "cpu",
            precision: str = "fp32") -> tuple[T, Timing]:
    """One fn: 1 cold + warmup + repeats calls -> (cold result, Timing)."""
    return measure_side_by_side({"fn": fn}, repeats, warmup, device, precision)["fn"]


def once(fn: Callable[[], T], device: str = "cpu", precision: str = "fp32") -> tuple[T, Timing]:
    """A single timed call, for work too long to repeat (a sweep, a brute-force grid): cold = median, IQR 0."""
    with precision_context(precision, device):
        out, seconds = timed(fn)
    return out, Timing(seconds, seconds, 0.0, [seconds], device, precision, torch.get_num_threads())


def precisions(device: str) -> list[str]:
    """Precisions a torch figure is measured in: fp32 on CPU; fp32, tf32 and bf16 (autocast) on CUDA."""
    return ["fp32", "tf32", "bf16"] if device.startswith("cuda") else ["fp32"]


@contextlib.contextmanager
def precision_context(name: str, device: str) -> Iterator[None]:
    """fp32: plain float32 matmuls (TF32 off); tf32: TF32 matmuls and convolutions (CUDA);
    bf16: torch.autocast to bfloat16 on the device (inputs and outputs stay float32 outside autocast ops)."""
    if name not in ("fp32", "tf32", "bf16"):
        raise ValueError(f"precision {name!r}: unknown (fp32 | tf32 | bf16)")
    cuda = device.startswith("cuda")
    saved = (torch.backends.cuda.matmul.allow_tf32, torch.backends.cudnn.allow_tf32)
    torch.backends.cuda.matmul.allow_tf32 = torch.backends.cudnn.allow_tf32 = cuda and name == "tf32"
    try:
        if name == "bf16":
            with torch.autocast(device_type="cuda" if cuda else "cpu", dtype=torch.bfloat16):
                yield
        else:
            yield
    finally:
        torch.backends.cuda.matmul.allow_tf32, torch.backends.cudnn.allow_tf32 = saved
