"""Where marching samples sit along a ray: s_p distances in [lo, hi] per ray."""

from __future__ import annotations

import numpy as np

STEP_RULES = ("uniform", "stratified", "geometric")


def marching_distances(rule: str, s_p: int, lo: float, hi: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(R, s_p) float64 distances, ascending along each row, within [lo, max(lo, hi)] for hi (R,).

    uniform:    i.i.d. uniform, sorted.
    stratified: one uniform draw in each of s_p equal strata.
    geometric:  one draw per stratum of log-distance: crowded toward lo (the surface), ratio (hi/lo)^(1/s_p).
    """
    hi = np.maximum(np.asarray(hi, np.float64), lo)[:, None]
    u = rng.random((hi.shape[0], s_p))
    if rule == "uniform":
        return lo + np.sort(u, axis=1) * (hi - lo)
    frac = (np.arange(s_p) + u) / s_p
    if rule == "stratified":
        return lo + frac * (hi - lo)
    return lo * (hi / lo) ** frac
