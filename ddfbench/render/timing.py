"""Render timing: the cold render (the first, with whatever setup the representation does lazily:
BVH commit, weights to the device, kernel compilation) apart from warm renders (median and IQR of
`repeats` renders after `warmup` untimed ones), each on ddfbench.core.clock's synchronized clock.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, TypeVar

from ddfbench.core.clock import median_iqr, timed

T = TypeVar("T")


@dataclass
class RenderTiming:
    """Seconds: cold (first render), warm median and interquartile range, every warm render in order; how many
    untimed warm-up renders ran between them."""

    cold_s: float
    warm_s: float
    warm_iqr_s: float
    warm_all_s: list[float]
    warmups: int

    @property
    def repeats(self) -> int:
        return len(self.warm_all_s)


def time_renders(render: Callable[[], T], repeats: int, warmup: int,
                 max_seconds: float = float("inf")) -> tuple[T, RenderTiming]:
    """Call `render` 1 + warmup + repeats times; return the first (cold) result and the timings.

    Once max_seconds of render time are spent, warm-up and repeats stop early (one timed warm
    render always runs), so a slow family costs seconds, not minutes; RenderTiming.repeats and .warmups say how many
    ran (no warm-up where the cold render alone spent max_seconds: the warm figure is then the second render).
    """
    first, cold = timed(render)
    spent, warmups = cold, 0
    for _ in range(warmup):
        if spent >= max_seconds:
            break
        spent += timed(render)[1]
        warmups += 1
    warm: list[float] = []
    for _ in range(repeats):
        warm.append(timed(render)[1])
        spent += warm[-1]
        if spent >= max_seconds:
            break
    return first, RenderTiming(cold, *median_iqr(warm), warm, warmups)
