"""Render timing: the cold render (the first, with whatever setup the representation does lazily:
BVH commit, weights to the device, kernel compilation) apart from warm renders (median and IQR of
`repeats` renders after `warmup` untimed ones). When torch has CUDA in use, every clock read waits
for the device (torch.cuda.synchronize), so queued kernels are counted. `timed` and `median_iqr`
(one call's seconds; the warm median and IQR) serve ddfbench.bench.timing too.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass
from typing import Callable, TypeVar

import numpy as np

T = TypeVar("T")


def _synchronize() -> None:
    torch = sys.modules.get("torch")  # only a process that already uses torch can have queued CUDA work
    if torch is not None and torch.cuda.is_available() and torch.cuda.is_initialized():
        torch.cuda.synchronize()


def compute_threads() -> int:
    """Threads a render may use: torch's intra-op threads where torch is loaded, else the CPU count."""
    torch = sys.modules.get("torch")
    return int(torch.get_num_threads()) if torch is not None else int(os.cpu_count() or 1)


def clock() -> float:
    """perf_counter seconds, after any queued CUDA work has finished."""
    _synchronize()
    return time.perf_counter()


def timed(fn: Callable[[], T]) -> tuple[T, float]:
    """(fn's result, its seconds on clock())."""
    start = clock()
    out = fn()
    return out, clock() - start


def median_iqr(seconds: list[float]) -> tuple[float, float]:
    """(median, interquartile range q75 − q25) of timed calls; seconds must not be empty."""
    q1, median, q3 = np.percentile(seconds, [25, 50, 75])
    return float(median), float(q3 - q1)


@dataclass
class RenderTiming:
    """Seconds: cold (first render), warm median and interquartile range, every warm render in order."""

    cold_s: float
    warm_s: float
    warm_iqr_s: float
    warm_all_s: list[float]

    @property
    def repeats(self) -> int:
        return len(self.warm_all_s)


def time_renders(render: Callable[[], T], repeats: int, warmup: int,
                 max_seconds: float = float("inf")) -> tuple[T, RenderTiming]:
    """Call `render` 1 + warmup + repeats times; return the first (cold) result and the timings.

    Once max_seconds of render time are spent, warm-up and repeats stop early (one timed warm
    render always runs), so a slow family costs seconds, not minutes; RenderTiming.repeats says how many ran.
    """
    first, cold = timed(render)
    spent = cold
    for _ in range(warmup):
        if spent >= max_seconds:
            break
        spent += timed(render)[1]
    warm: list[float] = []
    for _ in range(repeats):
        warm.append(timed(render)[1])
        spent += warm[-1]
        if spent >= max_seconds:
            break
    return first, RenderTiming(cold, *median_iqr(warm), warm)
