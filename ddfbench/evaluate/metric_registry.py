"""Every reported metric, declared once: where a record holds it, which way is better, what an empty
reconstruction scores, its table label and whether the record holds its noise floor.

The penalty path (`ddfbench.evaluate.metrics.penalty_metrics`), the report tables and plots and the paper
claims all read `METRICS`; adding a `Metric` here is all it takes for a new value the runner records
to reach every table, with its penalty for an empty reconstruction. Units: the normalized frame
(unit cube); `scale` only changes how a table prints a value.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ddfbench.core.geometry import BOX_HALF

# Domain-box diagonal for the default padded box (half-side BOX_HALF): the largest distance two points
# of the field domain can have. Empty reconstructions get the worst value this allows.
PENALTY_DISTANCE = float(2 * BOX_HALF * np.sqrt(3.0))
FLOOR_KEY = "noise_floor"  # record.metrics[FLOOR_KEY] mirrors record.metrics for GT vs a GT resample


@dataclass(frozen=True)
class Metric:
    """One reported value.

    name:    column name in summaries and CSVs (e.g. "chamfer_l2", "fscore@0.01")
    path:    keys into the record, e.g. ("metrics", "fscore", "0.01") or ("cost", "fit_s")
    label:   table header
    scale:   factor applied when printed (1e3 for "×10³" labels)
    better:  "low" | "high" | "" (a setting or a count: never marked best)
    penalty: the value an empty or failed reconstruction gets (None: not a geometry metric)
    floor:   the record also holds it under metrics.noise_floor (GT against a GT resample)
    shown:   printed in tables (False: recorded and penalized, CSV only)
    """

    name: str
    path: tuple[str, ...]
    label: str
    scale: float = 1.0
    better: str = "low"
    penalty: float | None = None
    floor: bool = False
    shown: bool = True

    def __post_init__(self) -> None:
        if self.better not in ("low", "high", ""):
            raise ValueError(f"metric {self.name}: better={self.better!r} (low | high | '')")

    def read(self, record: Mapping[str, Any]) -> float:
        """The metric's value in a record (NaN where absent or not a number)."""
        return _read(record, self.path)

    def read_floor(self, record: Mapping[str, Any]) -> float:
        """Its noise-floor value in a record (NaN where the metric has none)."""
        if not self.floor or self.path[0] != "metrics":
            return float("nan")
        return _read(record, ("metrics", FLOOR_KEY, *self.path[1:]))


def as_float(value: Any) -> float:
    """float(value); NaN where value is None or not a number."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return float("nan")


def _read(record: Mapping[str, Any], path: tuple[str, ...]) -> float:
    node: Any = record
    for key in path:
        if not isinstance(node, Mapping) or key not in node:
            return float("nan")
        node = node[key]
    return as_float(node)


def fscore(radius: float) -> Metric:
    """F-score at an unsquared radius; 0 for an empty reconstruction."""
    return Metric(f"fscore@{radius}", ("metrics", "fscore", str(radius)), f"F@{radius}", better="high",
                  penalty=0.0, floor=True)


def _sided(direction: str, label: str) -> list[Metric]:
    worst = PENALTY_DISTANCE**2
    return [Metric(f"sided_{direction}_{stat}", ("metrics", f"sided_{direction}", stat), f"{label} {stat} ×10³", 1e3,
                   penalty=worst, shown=stat == "mean") for stat in ("mean", "median", "p95")]


FSCORE_RADII = (0.001, 0.002, 0.005, 0.01, 0.02)  # conf/eval radii; 0.001, 0.002 resolve below the sampling floor
METRICS: list[Metric] = [
    Metric("chamfer_l2", ("metrics", "chamfer_l2"), "CD-L2 ×10³", 1e3, penalty=2 * PENALTY_DISTANCE**2, floor=True),
    Metric("chamfer_l1", ("metrics", "chamfer_l1"), "CD-L1 ×10³", 1e3, penalty=PENALTY_DISTANCE, floor=True),
    # exact distance of each sampled point to the other mesh: no sampling floor (GT against GT is 0)
    Metric("p2s_chamfer_l2", ("metrics", "p2s_chamfer_l2"), "p2s CD-L2 ×10³", 1e3, penalty=2 * PENALTY_DISTANCE**2),
    Metric("p2s_chamfer_l1", ("metrics", "p2s_chamfer_l1"), "p2s CD-L1 ×10³", 1e3, penalty=PENALTY_DISTANCE),
    *[fscore(r) for r in FSCORE_RADII],
    *_sided("gt_to_rec", "GT→rec"),
    *_sided("rec_to_gt", "rec→GT"),
    # mean signed distance of the reconstruction's points to GT (metrics.geometry_metrics; + outside, the opposite
    # of ddfbench.report.zero_level's field offset): a level set shifted off the surface; 0 is best in either direction,
    # so it is never marked best; none when empty
    Metric("level_offset", ("metrics", "level_offset"), "level offset ×10³ (+out)", 1e3, better=""),
    Metric("normal_consistency", ("metrics", "normal_consistency"), "NC", better="high", penalty=0.0),
    # topology of the reconstruction (metrics.topology); a table's mean of `closed` is the share of closed
    # meshes; an empty mesh is not closed and has no piece count (its row's cell says "(of k)")
    Metric("closed", ("metrics", "closed"), "closed", better="high", penalty=0.0),
    Metric("components", ("metrics", "components"), "components", better=""),
    Metric("mask_iou", ("metrics", "mask_iou"), "mask IoU", better="high"),
    Metric("depth_mae", ("metrics", "depth_mae"), "depth MAE ×10³", 1e3),
    Metric("normal_angle_deg", ("metrics", "normal_angle_deg"), "normal err °"),
    Metric("storage_bytes", ("cost", "storage_bytes"), "storage B"),
    Metric("n_params", ("cost", "n_params"), "params"),
    Metric("n_samples", ("sampling", "n_samples"), "samples", better=""),
    Metric("sampling_s", ("cost", "sampling_s"), "sample s"),
    Metric("steps", ("fit", "steps"), "steps", better=""),
    Metric("epochs", ("fit", "epochs"), "epochs", better=""),
    Metric("fit_s", ("cost", "fit_s"), "fit s"),
    Metric("extract_s", ("cost", "extract_s"), "extract s"),
    Metric("render_cold_s", ("cost", "render_cold_s"), "render cold s"),
    Metric("render_warm_s", ("cost", "render_warm_s"), "render warm s"),
]


def by_name() -> dict[str, Metric]:
    """{name: Metric} of the registry as it is now."""
    return {m.name: m for m in METRICS}


def _objective(name: str) -> Metric:
    """The registry's metric `name` as an objective: an InputError for an unknown name or a setting or count."""
    from ddfbench.core.errors import InputError

    metric = by_name().get(name)
    if metric is None:
        raise InputError(f"objective={name}: not a metric (known: {', '.join(m.name for m in METRICS)})")
    if not metric.better:
        raise InputError(f"objective={name}: a setting or count, with no better end to optimize toward")
    return metric


def check_objective(name: str, direction: str) -> None:
    """An InputError where a study that optimizes in `direction` ("minimize" | "maximize") would run away from
    the better end of metric `name` (e.g. minimizing an F-score), or where `name` is no objective."""
    from ddfbench.core.errors import InputError

    metric = _objective(name)
    wanted = {"minimize": "low", "maximize": "high"}.get(direction)
    if wanted is None:
        raise InputError(f"hydra.sweeper.direction={direction}: minimize or maximize")
    if metric.better != wanted:
        raise InputError(f"objective={name}: {metric.better}er is better, and the study would {direction} it "
                         f"(hydra.sweeper.direction={direction})")


def objective_value(record: Mapping[str, Any], name: str) -> float:
    """Metric `name` of a record as an optimizer's objective: its empty-reconstruction penalty where the
    run failed or holds no finite value (without one, its worst end: inf where lower is better, -inf where higher).
    A name that is no metric, or a setting or count, is an InputError."""
    metric = _objective(name)
    value = metric.read(record) if record.get("status") == "ok" else float("nan")
    if np.isfinite(value):
        return value
    if metric.penalty is not None:
        return float(metric.penalty)
    return float("inf") if metric.better == "low" else float("-inf")


def penalties() -> dict[str, Any]:
    """The nested `record.metrics` dict of an empty reconstruction: every declared penalty at its path."""
    out: dict[str, Any] = {}
    for m in METRICS:
        if m.penalty is None or m.path[0] != "metrics":
            continue
        node = out
        for key in m.path[1:-1]:
            node = node.setdefault(key, {})
        node[m.path[-1]] = m.penalty
    return out
