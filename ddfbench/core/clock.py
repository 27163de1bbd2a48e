"""A wall clock that counts queued GPU work: `clock` waits for the device (torch.cuda.synchronize) when
torch has CUDA in use, so asynchronous kernels are inside the interval. `timed` (one call's seconds),
`median_iqr` (warm median and IQR) and `compute_threads` serve training, rendering and the benches; this
module imports nothing of ddfbench, so any layer may use it.
"""

from __future__ import annotations

import os
import sys
import time
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
