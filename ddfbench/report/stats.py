"""Statistics over seeds: mean, std, a Student t 95 % interval, interval overlap, the one-sample t test's p, and
Holm's correction of a family of p values (Holm 1979: step-down, controls the family-wise error). Paired
differences: report.paired.

The interval is the t interval of the mean over seeds, mean ± t(0.975, n−1)·s/√n, cut to the metric's range in
tables (within_range); it needs n ≥ 2 (NaN bounds otherwise). It assumes roughly normal seed-to-seed scatter; with n = 3 it is wide
(t = 4.30), which is the honest width at that n.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np
from scipy import stats as _scipy_stats

LEVEL = 0.95
INTERVAL_NAME = "t interval of the mean over seeds, 95 %"


@dataclass(frozen=True)
class Summary:
    """mean, sample std (ddof 1), n finite values, and the t interval [lo, hi] of the mean."""

    mean: float
    std: float
    n: int
    lo: float
    hi: float


def summarize_values(values: Iterable[float], level: float = LEVEL) -> Summary:
    """Summary of the finite values (NaN everywhere when there are none; NaN std/bounds when n = 1)."""
    v = np.asarray([x for x in values if x is not None], dtype=float)
    v = v[np.isfinite(v)]
    n = len(v)
    if n == 0:
        return Summary(math.nan, math.nan, 0, math.nan, math.nan)
    mean = float(v.mean())
    if n == 1:
        return Summary(mean, math.nan, 1, math.nan, math.nan)
    std = float(v.std(ddof=1))
    half = float(_scipy_stats.t.ppf(0.5 + level / 2, n - 1)) * std / math.sqrt(n)
    return Summary(mean, std, n, mean - half, mean + half)


def t_test_p(s: Summary, against: float = 0.0) -> float:
    """Two-sided p of the one-sample t test of the mean against `against` (NaN below n = 2; with no spread 0, or 1
    when the mean is `against` itself)."""
    if s.n < 2:
        return math.nan
    if not s.std > 0:
        return 0.0 if s.mean != against else 1.0
    t = (s.mean - against) / (s.std / math.sqrt(s.n))
    return float(2 * _scipy_stats.t.sf(abs(t), s.n - 1))


def holm(pvalues: Iterable[float]) -> list[float]:
    """Holm-adjusted p values in the input order (NaN stays NaN and is not counted in the family)."""
    p = list(pvalues)
    order = sorted((i for i, x in enumerate(p) if math.isfinite(x)), key=lambda i: p[i])
    m, out, running = len(order), [math.nan] * len(p), 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        out[i] = running
    return out


SHARES = ("fscore@", "mask_iou", "normal_consistency", "closed")  # values in [0, 1]
SIGNED = ("level_offset",)  # a signed offset: any real value


def metric_range(name: str) -> tuple[float, float]:
    """The values a reported metric can take: [0, 1] for shares (F-scores, IoU, normal consistency, the closed
    flag), [0, 180] for angles in degrees, the real line for signed offsets, [0, inf) for the rest (distances,
    times, sizes, counts)."""
    if name.startswith(SHARES):
        return 0.0, 1.0
    if name.startswith(SIGNED):
        return -math.inf, math.inf
    return (0.0, 180.0) if name.endswith("_deg") else (0.0, math.inf)


def within_range(s: Summary, name: str, bounds: tuple[float, float] | None = None) -> Summary:
    """s with its interval cut to the metric's range (metric_range(name), or `bounds`): the true mean lies in the
    range, so the cut interval covers it whenever the t interval does (same level), and no bound reads as a value
    the metric cannot take."""
    lo, hi = bounds or metric_range(name)
    return Summary(s.mean, s.std, s.n, min(max(s.lo, lo), hi), max(min(s.hi, hi), lo)) if s.n > 1 else s


def sig3(x: float | None, scale: float = 1.0) -> str:
    """x · scale to 3 significant digits, or "–" where x is None or not finite (a missing value in a table)."""
    return f"{x * scale:.3g}" if x is not None and math.isfinite(x) else "–"


def overlaps(a: tuple[float, float], b: tuple[float, float]) -> bool:
    """Whether two intervals [lo, hi] share a point; an interval with a NaN bound (n < 2) overlaps all."""
    if not all(math.isfinite(x) for x in (*a, *b)):
        return True
    return a[0] <= b[1] and b[0] <= a[1]


def best_and_ties(means: Sequence[float], intervals: Sequence[tuple[float, float]], better: str) -> dict[int, str]:
    """{index: "best" | "tie"}: the best mean is "best" only when its interval overlaps no other row's;
    otherwise it and every row whose interval overlaps it are "tie". Nothing is marked when fewer
    than two finite means differ."""
    idx = [i for i, m in enumerate(means) if math.isfinite(m)]
    if len(idx) < 2 or better not in ("low", "high") or len({means[i] for i in idx}) < 2:
        return {}
    best = (min if better == "low" else max)(idx, key=lambda i: means[i])
    tied = [i for i in idx if i != best and (means[i] == means[best] or overlaps(intervals[i], intervals[best]))]
    if not tied:
        return {best: "best"}
    return {i: "tie" for i in [best, *tied]}


def welch_ratio(a: np.ndarray, b: np.ndarray, level: float = LEVEL) -> dict[str, float]:
    """Two unpaired samples of logs, a (n_a,) and b (n_b,): exp(mean(a) - mean(b)) as "ratio" with its Welch t
    interval ("lo", "hi") and the two-sided "p" (only "ratio" when both samples are constant)."""
    va, vb = a.var(ddof=1) / len(a), b.var(ddof=1) / len(b)
    diff, se = float(a.mean() - b.mean()), math.sqrt(va + vb)
    if se == 0:
        return {"ratio": math.exp(diff)}
    dof = (va + vb) ** 2 / (va**2 / (len(a) - 1) + vb**2 / (len(b) - 1))
    half = float(_scipy_stats.t.ppf(0.5 + level / 2, dof)) * se
    p = float(2 * _scipy_stats.t.sf(abs(diff) / se, dof))
    return {"ratio": math.exp(diff), "lo": math.exp(diff - half), "hi": math.exp(diff + half), "p": p}
