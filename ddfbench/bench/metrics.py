"""Section 6, metrics: chamfer (L2, L1) + f-score + sided distances between two point clouds
(ddfbench.evaluate.metrics.cloud_metrics) at each size, against the bare KD-tree work they need (a cKDTree
built on each cloud and queried with the other, all cores), measured in the same process.

Clouds: `n` seeded area-uniform samples of the shape, twice (independent seeds). Target: 100k x 100k
within 1.5 s on 2 cores (the value itself, this machine's core count in the details).
Sizes: shape, points (list), repeats_max_points (larger clouds are timed once).
"""

from __future__ import annotations

import os

from scipy.spatial import cKDTree

from ddfbench.bench.context import Context
from ddfbench.bench.results import SectionResult, Target, compare
from ddfbench.bench.timing import measure_side_by_side, once
from ddfbench.evaluate.metrics import cloud_metrics, sample_surface

RADII = (0.005, 0.01, 0.02)
TARGET_POINTS, TARGET = 100_000, Target("<=", 1.5, on="value")


def bare_kdtree(a, b) -> None:
    """The floor of the work: nearest neighbours both ways with scipy's cKDTree."""
    cKDTree(b).query(a, k=1, workers=-1)
    cKDTree(a).query(b, k=1, workers=-1)


def run(ctx: Context) -> SectionResult:
    s = ctx.sizes
    mesh = ctx.shape(s["shape"]).mesh
    result = SectionResult(details={"cpu_count": os.cpu_count(), "radii": list(RADII)})
    for n in (int(p) for p in s["points"]):
        a, b = sample_surface(mesh, n, 0)[0], sample_surface(mesh, n, 1)[0]
        fns = {"metrics": lambda: cloud_metrics(a, b, RADII), "bare": lambda: bare_kdtree(a, b)}
        if n <= int(s["repeats_max_points"]):
            timed = measure_side_by_side(fns, ctx.repeats, ctx.warmup)
            metric_t, bare_t = timed["metrics"][1], timed["bare"][1]
        else:
            metric_t, bare_t = once(fns["metrics"])[1], once(fns["bare"])[1]
        result.details[f"n={n}"] = {"metrics": metric_t.as_dict(), "bare_kdtree": bare_t.as_dict()}
        result.rows.append(compare(
            "metrics", f"chamfer + f-score + sided distance, {n} x {n} points: seconds", metric_t.median_s, "s",
            "bare cKDTree build + query both ways, seconds", bare_t.median_s, inverse=True, device="cpu",
            threads=os.cpu_count() or 1, target=TARGET if n == TARGET_POINTS else None,
            note="ratio = KD-tree seconds / metric seconds: 1 = the metrics add nothing to the nearest-neighbour "
                 "work (above 1 is noise); KD-tree queries use all cores"))
    return result
