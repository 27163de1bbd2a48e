"""Inference over shapes: per-shape means over seeds first, then one interval over the shapes.

Seeds of one shape are not independent replicates of the population of shapes, so a claim about "shapes"
gets n = the number of shapes. Every interval here stays inside its metric's range by construction:

    positive, unbounded (chamfer, seconds, bytes)   geometric mean over shapes, t interval of the mean log,
                                                     exponentiated: bounds > 0
    bounded in [0, 1] (F-score, normal consistency) mean over shapes, bootstrap percentile interval of the
                                                     mean (seeded): bounds inside [min, max] of the shape means
    a ratio a / b of two settings                    per shape ln(mean a / mean b); geometric mean ratio and the
                                                     exponentiated t interval of the mean log ratio; its
                                                     two-sided p (H0: ratio 1) for Holm's correction

`holm` adjusts the p values of one family of claims (Holm 1979: step-down, controls the family-wise error).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Mapping

import numpy as np
from scipy import stats as _scipy_stats

from ddfbench.report.stats import LEVEL

BOOTSTRAP_RESAMPLES = 10000
BOOTSTRAP_SEED = 0


@dataclass(frozen=True)
class OverShapes:
    """A center with its 95 % interval over n shapes; p: two-sided p of H0 (ratio 1), NaN where not a ratio."""

    center: float
    lo: float
    hi: float
    n: int
    p: float = math.nan


def shape_means(values: Iterable[tuple[str, float]]) -> dict[str, float]:
    """{shape: mean over its finite values} from (shape, value) pairs (one pair per seed)."""
    by_shape: dict[str, list[float]] = {}
    for shape, value in values:
        if value is not None and math.isfinite(value):
            by_shape.setdefault(shape, []).append(float(value))
    return {shape: float(np.mean(v)) for shape, v in by_shape.items()}


def _t_half(logs: np.ndarray, level: float) -> float:
    return float(_scipy_stats.t.ppf(0.5 + level / 2, len(logs) - 1) * logs.std(ddof=1) / math.sqrt(len(logs)))


def geometric(per_shape: Mapping[str, float], level: float = LEVEL) -> OverShapes:
    """Geometric mean of positive per-shape values and the exponentiated t interval of their mean log."""
    logs = np.log([v for v in per_shape.values() if v > 0])
    if len(logs) == 0:
        return OverShapes(math.nan, math.nan, math.nan, 0)
    center = float(np.exp(logs.mean()))
    if len(logs) == 1:
        return OverShapes(center, math.nan, math.nan, 1)
    half = _t_half(logs, level)
    return OverShapes(center, float(np.exp(logs.mean() - half)), float(np.exp(logs.mean() + half)), len(logs))


def bounded(per_shape: Mapping[str, float], level: float = LEVEL) -> OverShapes:
    """Mean of per-shape values in a bounded range and the bootstrap percentile interval of the mean over shapes."""
    v = np.asarray(list(per_shape.values()), float)
    if len(v) == 0:
        return OverShapes(math.nan, math.nan, math.nan, 0)
    if len(v) == 1:
        return OverShapes(float(v[0]), math.nan, math.nan, 1)
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    means = v[rng.integers(0, len(v), size=(BOOTSTRAP_RESAMPLES, len(v)))].mean(axis=1)
    lo, hi = np.quantile(means, [0.5 - level / 2, 0.5 + level / 2])
    return OverShapes(float(v.mean()), float(lo), float(hi), len(v))


def ratio(a: Mapping[str, float], b: Mapping[str, float], level: float = LEVEL) -> OverShapes:
    """Geometric mean over the shared shapes of a / b (both > 0), its interval and the t test's two-sided p."""
    logs = np.asarray([math.log(a[s] / b[s]) for s in a if s in b and a[s] > 0 and b[s] > 0])
    if len(logs) == 0:
        return OverShapes(math.nan, math.nan, math.nan, 0)
    center = float(np.exp(logs.mean()))
    if len(logs) == 1 or np.ptp(logs) < 1e-12:  # one shape, or the same ratio on all: no spread to test
        return OverShapes(center, math.nan, math.nan, len(logs))
    half = _t_half(logs, level)
    p = float(_scipy_stats.ttest_1samp(logs, 0.0).pvalue)
    return OverShapes(center, float(np.exp(logs.mean() - half)), float(np.exp(logs.mean() + half)), len(logs), p)


def holm(pvalues: Iterable[float]) -> list[float]:
    """Holm-adjusted p values in the input order (NaN stays NaN and is not counted in the family)."""
    p = list(pvalues)
    order = sorted((i for i, x in enumerate(p) if math.isfinite(x)), key=lambda i: p[i])
    m, out, running = len(order), [math.nan] * len(p), 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        out[i] = running
    return out
