"""Inference over shapes: per-shape means over seeds first, then one interval over the shapes.

Seeds of one shape are not independent replicates of the population of shapes, so a claim about "shapes"
gets n = the number of shapes. Every interval here stays inside its metric's range by construction:

    positive, unbounded (chamfer, seconds, bytes)   geometric mean over shapes, t interval of the mean log,
                                                     exponentiated: bounds > 0
    a share in [0, 1] (F-score, normal consistency)  the arithmetic mean over shapes and its t interval cut to
                                                     [0, 1] (a mean logit would hinge on how a share of exactly 0 or
                                                     1, common for the F-score, is clipped)
    a ratio a / b of two settings                    per shape ln(mean a / mean b); geometric mean ratio and the
                                                     exponentiated t interval of the mean log ratio; its
                                                     two-sided p (H0: ratio 1) for Holm's correction (the same
                                                     ratio on every shape: a zero-width interval, p 0)

Holm's correction of a family of such p values: report.stats.holm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Mapping

import numpy as np
from scipy import stats as _scipy_stats

from ddfbench.report.stats import LEVEL, Summary, summarize_values, within_range


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


def exponentiated(s: Summary, p: float = math.nan) -> OverShapes:
    """A Summary of logs as exp of its mean and of its t interval (NaN bounds below n = 2; all NaN, n 0, for none)."""
    return OverShapes(math.exp(s.mean), math.exp(s.lo), math.exp(s.hi), s.n, p)


def _exp(logs: np.ndarray, level: float, p: float = math.nan) -> OverShapes:
    """exp of the mean of logs and of its t interval (NaN bounds below n = 2)."""
    return exponentiated(summarize_values(logs, level), p)


def geometric(per_shape: Mapping[str, float], level: float = LEVEL) -> OverShapes:
    """Geometric mean of per-shape values and the exponentiated t interval of their mean log. A value <= 0 has no
    log: it is left out (n says how many remain)."""
    return _exp(np.log([v for v in per_shape.values() if v > 0]), level)


def share_mean(per_shape: Mapping[str, float], level: float = LEVEL) -> OverShapes:
    """Mean of per-shape shares in [0, 1] and its t interval cut to [0, 1] (NaN bounds below n = 2)."""
    if not per_shape:
        return OverShapes(math.nan, math.nan, math.nan, 0)
    s = within_range(summarize_values(list(per_shape.values()), level), "share", (0.0, 1.0))
    return OverShapes(s.mean, s.lo, s.hi, s.n)


def _log_ratios(a: Mapping[str, float], b: Mapping[str, float]) -> np.ndarray:
    """ln(a / b) over the shapes both have, where both are > 0."""
    return np.asarray([math.log(a[s] / b[s]) for s in a if s in b and a[s] > 0 and b[s] > 0])


def ratio(a: Mapping[str, float], b: Mapping[str, float], level: float = LEVEL) -> OverShapes:
    """Geometric mean over the shared shapes of a / b (both > 0), its interval and the t test's two-sided p."""
    logs = _log_ratios(a, b)
    if len(logs) >= 2 and np.ptp(logs) < 1e-12:  # the same ratio on every shape: no spread, no doubt
        center = float(np.exp(logs.mean()))
        return OverShapes(center, center, center, len(logs), ratio_p(a, b))
    return _exp(logs, level, ratio_p(a, b))


def ratio_p(a: Mapping[str, float], b: Mapping[str, float], against: float = 1.0) -> float:
    """Two-sided p of the t test of the mean log of a / b over the shared shapes (both > 0) against log(against):
    the test of "the ratio is `against`", e.g. an equivalence bound (NaN below n = 2; 0 or 1 with no spread)."""
    logs = _log_ratios(a, b)
    if len(logs) < 2:
        return math.nan
    if np.ptp(logs) < 1e-12:
        return 0.0 if abs(logs.mean() - math.log(against)) > 1e-12 else 1.0
    return float(_scipy_stats.ttest_1samp(logs, math.log(against)).pvalue)


def fmt(s: OverShapes, scale: float = 1.0) -> str:
    """'center [lo, hi] (n N)' at 3 significant digits, times scale ('–' without a center, no bounds below n 2)."""
    if not math.isfinite(s.center):
        return "–"
    bounds = f" [{s.lo * scale:.3g}, {s.hi * scale:.3g}]" if math.isfinite(s.lo) else ""
    return f"{s.center * scale:.3g}{bounds} (n {s.n})"
