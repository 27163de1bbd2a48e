"""Convergence over a long fit: probe curves per seed, their median and min–max band, time to reach
k × the noise floor (`+experiment=convergence`).

A run's curve is its accuracy probes (record fit.probes: seconds of training, chamfer_l2, fscore@r).
Between probes a curve holds its last value (a step function: nothing is interpolated that was not
measured). The band at time t is over the seeds that have probed by t.
"""

from __future__ import annotations

import math
from typing import Any, Iterable

import numpy as np

from ddfbench.metric_registry import by_name
from ddfbench.report.records import Record, ok_records, shape_name

FLOOR_MULTIPLES = (5.0, 2.0)  # time-to-reach k x the chamfer noise floor
NOT_REACHED = "not reached"


def curve(rec: Record, metric: str) -> tuple[np.ndarray, np.ndarray]:
    """(seconds (P,), values (P,)) of a run's finite probes of `metric`, by time."""
    pts = [(float(p.get("seconds", math.nan)), float(p.get(metric, math.nan)))
           for p in (rec.get("fit") or {}).get("probes") or []]
    pts = sorted((s, v) for s, v in pts if math.isfinite(s) and math.isfinite(v))
    return (np.array([s for s, _ in pts]), np.array([v for _, v in pts])) if pts else (np.zeros(0), np.zeros(0))


def curves(records: Iterable[Record], metric: str) -> dict[tuple[str, str], list[tuple[np.ndarray, np.ndarray]]]:
    """{(model, shape): one curve per ok run with at least one probe}."""
    out: dict[tuple[str, str], list[tuple[np.ndarray, np.ndarray]]] = {}
    for r in ok_records(records):
        c = curve(r, metric)
        if len(c[0]):
            out.setdefault((str(r.get("model")), shape_name(r)), []).append(c)
    return out


def band(runs: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(times (T,), median (T,), min (T,), max (T,)) over the runs at every probe time of any run,
    each run holding its last probed value; a time before some run's first probe uses the runs that
    have probed."""
    times = np.unique(np.concatenate([t for t, _ in runs]))
    held = np.full((len(runs), len(times)), np.nan)
    for i, (t, v) in enumerate(runs):
        idx = np.searchsorted(t, times, side="right") - 1
        held[i, idx >= 0] = v[idx[idx >= 0]]
    return times, np.nanmedian(held, axis=0), np.nanmin(held, axis=0), np.nanmax(held, axis=0)


def time_to_reach(t: np.ndarray, v: np.ndarray, threshold: float, better: str = "low") -> float:
    """Seconds of training at the first probe at or past `threshold` (inf if none)."""
    hit = v <= threshold if better == "low" else v >= threshold
    return float(t[np.argmax(hit)]) if hit.any() else math.inf


def floor(records: Iterable[Record], shape: str | None = None, metric: str = "chamfer_l2") -> float:
    """Mean noise floor of `metric` over the ok records of `shape` (of every shape where None; NaN if none)."""
    m = by_name()[metric]
    vals = [m.read_floor(r) for r in ok_records(records) if shape is None or shape_name(r) == shape]
    vals = [v for v in vals if math.isfinite(v)]
    return float(np.mean(vals)) if vals else math.nan


def time_to_floor_rows(records: list[Record], metric: str = "chamfer_l2") -> list[dict[str, Any]]:
    """Per (model, shape): seeds n, and per k in FLOOR_MULTIPLES the median seconds to reach k x floor
    over the seeds (NOT_REACHED when fewer than half the seeds got there) and how many did."""
    rows = []
    for (model, shape), runs in curves(records, metric).items():
        f = floor(records, shape, metric)
        row: dict[str, Any] = {"model": model, "shape": shape, "n": len(runs), "floor": f,
                               "budget_s": max(float(t[-1]) for t, _ in runs)}
        for k in FLOOR_MULTIPLES:
            times = [time_to_reach(t, v, k * f) for t, v in runs] if math.isfinite(f) else [math.inf] * len(runs)
            reached = [x for x in times if math.isfinite(x)]
            row[f"reached_{k:g}x"] = len(reached)
            row[f"median_s_{k:g}x"] = float(np.median(times)) if 2 * len(reached) >= len(runs) else math.inf
        rows.append(row)
    return rows


def to_markdown(rows: list[dict[str, Any]]) -> str:
    """The time-to-floor table (chamfer L2)."""
    ks = FLOOR_MULTIPLES
    lines = ["| model | shape | seeds | floor ×10³ | " + " | ".join(f"time to {k:g}× floor (s)" for k in ks)
             + " | last probe (s) |", "|---" * (5 + len(ks)) + "|"]
    for r in rows:
        cells = []
        for k in ks:
            s = r[f"median_s_{k:g}x"]
            cells.append((f"{s:.3g}" if math.isfinite(s) else NOT_REACHED) + f" ({r[f'reached_{k:g}x']}/{r['n']})")
        lines.append(f"| {r['model']} | {r['shape']} | {r['n']} | {r['floor'] * 1e3:.4g} | " + " | ".join(cells)
                     + f" | {r['budget_s']:.0f} |")
    lines += ["", "Seconds of training (probes excluded) at the first probe whose chamfer L2 is at most k × the "
              "noise floor; median over seeds, (reached/seeds); 'not reached' where fewer than half the seeds got "
              "there within the budget. Probes are log-spaced, so a time is the probe's, an upper bound."]
    return "\n".join(lines) + "\n"
