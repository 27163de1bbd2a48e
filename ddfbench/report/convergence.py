"""Convergence over a long fit: probe curves per seed, their median and min–max band, time to reach
k × the noise floor, how many runs diverged, and every probe as a table (`+experiment=convergence`,
`paper_ddf`, `gan_epochs`).

A run's curve is its accuracy probes (record fit.probes: seconds of training, chamfer_l2, fscore@r).
Between probes a curve holds its last value (a step function: nothing is interpolated that was not
measured). The band at time t is over the seeds that have probed by t.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Any, Iterable

import numpy as np

from ddfbench.evaluate.metric_registry import by_name
from ddfbench.report.records import OFF_SHAPE_RULE, Record, empty_mesh, off_shape, ok_records, shape_name
from ddfbench.report.stats import sig3
from ddfbench.report.tables import pipe_lines

FLOOR_MULTIPLES = (5.0, 2.0)  # time-to-reach k x the chamfer noise floor
NOT_REACHED = "not reached"
REGRESSION = 2.0  # a run regressed when its last probe's chamfer L2 is over this multiple of its best probe's


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
    """Seconds of training at the first probe at or past `threshold` (inf if none): t (P,) fit seconds and
    v (P,) the metric at each of a run's P probes, in step order; better "low" (chamfer) or "high" (F-score)."""
    hit = v <= threshold if better == "low" else v >= threshold
    return float(t[np.argmax(hit)]) if hit.any() else math.inf


def floor(records: Iterable[Record], shape: str | None = None, metric: str = "chamfer_l2") -> float:
    """Mean noise floor of `metric` over the ok records of `shape` (of every shape where None; NaN if none)."""
    m = by_name()[metric]
    vals = [m.read_floor(r) for r in ok_records(records) if shape is None or shape_name(r) == shape]
    vals = [v for v in vals if math.isfinite(v)]
    return float(np.mean(vals)) if vals else math.nan


def time_to_floor_rows(records: list[Record], metric: str = "chamfer_l2") -> list[dict[str, Any]]:
    """Per (model, shape): seeds n, and per k in FLOOR_MULTIPLES the lower median of the seconds to reach k x floor
    over the seeds (NOT_REACHED when fewer than half the seeds got there) and how many did. A failed run (e.g. a
    diverged loss) counts as a seed that never got there."""
    cells = curves(records, metric)
    failed = Counter((str(r.get("model")), shape_name(r)) for r in records if r.get("status") == "failed")
    rows = []
    for model, shape in list(cells) + [c for c in failed if c not in cells]:
        runs = cells.get((model, shape), [])
        n = len(runs) + failed[(model, shape)]
        f = floor(records, shape, metric)
        row: dict[str, Any] = {"model": model, "shape": shape, "n": n, "floor": f,
                               "budget_s": max((float(t[-1]) for t, _ in runs), default=math.nan)}
        for k in FLOOR_MULTIPLES:
            reach = [time_to_reach(t, v, k * f) for t, v in runs] if math.isfinite(f) else [math.inf] * len(runs)
            times = reach + [math.inf] * failed[(model, shape)]
            reached = [x for x in times if math.isfinite(x)]
            row[f"reached_{k:g}x"] = len(reached)
            # the lower median: with half the seeds there (the rest inf), the slower of the middle pair that did
            row[f"median_s_{k:g}x"] = sorted(times)[(len(times) - 1) // 2] if 2 * len(reached) >= n else math.inf
        rows.append(row)
    return rows


def to_markdown(rows: list[dict[str, Any]]) -> str:
    """The time-to-floor table (chamfer L2)."""
    ks = FLOOR_MULTIPLES
    header = ["model", "shape", "seeds", "floor ×10³", *(f"time to {k:g}× floor (s)" for k in ks), "last probe (s)"]
    cells = []
    for r in rows:
        times = []
        for k in ks:
            s = r[f"median_s_{k:g}x"]
            times.append((f"{s:.3g}" if math.isfinite(s) else NOT_REACHED) + f" ({r[f'reached_{k:g}x']}/{r['n']})")
        floor_cell = f"{r['floor'] * 1e3:.4g}" if math.isfinite(r["floor"]) else "–"  # no ok run of the shape
        cells.append([f"{r['model']}", f"{r['shape']}", f"{r['n']}", floor_cell, *times,
                      f"{r['budget_s']:.0f}" if math.isfinite(r["budget_s"]) else "–"])
    lines = pipe_lines(header, cells)
    lines += ["", "Seconds of training (probes excluded) at the first probe whose chamfer L2 is at most k × the "
              "noise floor; median over seeds (the lower of the middle two at an even count), (reached/seeds); "
              "'not reached' where fewer than half the seeds got there within the budget. Probes are log-spaced, so "
              "a time is the probe's, an upper bound."]
    return "\n".join(lines) + "\n"


def _probe_column(key: str) -> tuple[bool, bool, str]:
    """The order of a probe's columns, whatever the record's key order (a compact record's keys are sorted):
    seconds, chamfer_l2, then the others by name (fscore@r by radius)."""
    return key != "seconds", key != "chamfer_l2", key


def probe_rows(records: list[Record]) -> list[dict[str, Any]]:
    """One row per probe of every ok run, ordered by model, shape, seed and step: model, shape, seed, key,
    step, epoch (step x the fit's epochs / steps; NaN where the record has no epoch count), seconds of
    training, and each metric the probe holds (chamfer_l2 in the record's units, fscore@r)."""
    rows = []
    for r in ok_records(records):
        fit = r.get("fit") or {}
        steps, epochs = float(fit.get("steps") or 0), float(fit.get("epochs") or math.nan)
        for p in fit.get("probes") or []:
            step = int(p.get("step", 0))
            rows.append({"model": str(r.get("model")), "shape": shape_name(r),
                         "seed": int((r.get("config") or {}).get("seed", 0)), "key": r.get("key"), "step": step,
                         "epoch": step * epochs / steps if steps > 0 else math.nan,
                         **{k: p[k] for k in sorted((k for k in p if k != "step"), key=_probe_column)}})
    return sorted(rows, key=lambda x: (x["model"], x["shape"], x["seed"], str(x["key"]), x["step"]))


def probe_markdown(rows: list[dict[str, Any]]) -> str:
    """The probe table: chamfer L2 x10^3 and F@0.01 at each probe of each run."""
    lines = ["| model | shape | seed | step | epoch | fit s | CD-L2 ×10³ | F@0.01 |", "|---" * 8 + "|"]
    for r in rows:
        f, epoch = r.get("fscore@0.01", math.nan), sig3(r["epoch"])
        lines.append(f"| {r['model']} | {r['shape']} | {r['seed']} | {r['step']:,} | {epoch} "
                     f"| {r['seconds']:.4g} | {r['chamfer_l2'] * 1e3:.4g} | {f:.3g} |")
    lines += ["", "Each run's accuracy probes as its record holds them (fit.probes): the probe mesh's resolution "
              "(train.probe_resolution) and point count (train.probe_points) are the probe's, not the final "
              "evaluation's, so a last probe need not equal the run's final metrics. fit s: seconds of training "
              "at the probe (probes excluded); epoch: step × the fit's epochs / steps. probes.csv has every "
              "F-score radius."]
    return "\n".join(lines) + "\n"


def stability_rows(records: list[Record]) -> list[dict[str, Any]]:
    """Per (model, shape), over every run (failed ones included): runs; nonfinite (the fit stopped on a
    non-finite loss or weight: record fit.stop "nonfinite"); failed_other (failed for another reason: not a
    divergence); empty (an ok run whose final mesh is empty); off (an ok run whose final mesh is off the
    shape, records.off_shape); regressed (an ok run whose last probe's chamfer L2 is over REGRESSION x its
    best probe's); diverged (runs with any of nonfinite, empty, off, regressed); worst_ratio (the largest
    last/best probe chamfer over the ok runs with probes, NaN if none)."""
    rows: dict[tuple[str, str], dict[str, Any]] = {}
    for r in records:
        row = rows.setdefault((str(r.get("model")), shape_name(r)), {
            "model": str(r.get("model")), "shape": shape_name(r), "runs": 0, "nonfinite": 0, "failed_other": 0,
            "empty": 0, "off": 0, "regressed": 0, "diverged": 0, "worst_ratio": math.nan})
        row["runs"] += 1
        if r.get("status") != "ok":
            nonfinite = (r.get("fit") or {}).get("stop") == "nonfinite"
            row["nonfinite" if nonfinite else "failed_other"] += 1
            row["diverged"] += nonfinite
            continue
        empty, off = empty_mesh(r), off_shape(r)
        _, v = curve(r, "chamfer_l2")
        ratio = float(v[-1] / v.min()) if len(v) and v.min() > 0 else math.nan
        regressed = ratio > REGRESSION
        row["worst_ratio"] = float(np.fmax(row["worst_ratio"], ratio))  # fmax skips a NaN side
        row["empty"] += empty
        row["off"] += off
        row["regressed"] += regressed
        row["diverged"] += empty or off or regressed
    return list(rows.values())


def stability_markdown(rows: list[dict[str, Any]]) -> str:
    """The divergence table."""
    lines = ["| model | shape | runs | diverged | stopped non-finite | empty mesh | off the shape | regressed "
             "| worst last/best probe | failed otherwise |", "|---" * 10 + "|"]
    for r in rows:
        ratio = sig3(r["worst_ratio"])
        lines.append(f"| {r['model']} | {r['shape']} | {r['runs']} | {r['diverged']} of {r['runs']} | {r['nonfinite']} "
                     f"| {r['empty']} | {r['off']} | {r['regressed']} | {ratio} | {r['failed_other']} |")
    lines += ["", f"A run diverged when its fit stopped on a non-finite loss or weight, its final mesh is empty or "
              f"off the shape ({OFF_SHAPE_RULE}: no sampled point of either surface near the other), or it regressed: its last probe's chamfer L2 is over "
              f"{REGRESSION:g}× its best probe's (worst last/best: "
              "the largest such ratio over the finished runs; 1 means the last probe was the best; an empty probe "
              "mesh scores the chamfer penalty). A run that failed for another reason (input, disk, extraction or "
              "metrics) is not counted as a divergence. runs: the records found; a sweep's missing runs are "
              "listed in report.md's status."]
    return "\n".join(lines) + "\n"
