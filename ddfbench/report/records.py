"""Run records as the report modules read them.

A record is the dict one run writes to <out_dir>/<experiment>/<key>/record.json (ddfbench.runs):
status ("ok" | "failed"), model (the preset label), shape {"name"}, config (the semantic config,
seed included), metrics (chamfer_l2, fscore, noise_floor, ...), cost (fit_s, render_warm_s, ...),
sampling, fit (steps, probes, ...). Values may be missing, None, or a string such as "inf" (the
writer's strict JSON). These helpers read the fields every report module needs: which runs
finished, the shape, a number, and the chamfer L2 (through ddfbench.metric_registry).
"""

from __future__ import annotations

from typing import Any, Iterable

from ddfbench.metric_registry import as_float, by_name

__all__ = ["Record", "as_float", "chamfer_l2", "ok_records", "shape_name"]

Record = dict[str, Any]


def ok_records(records: Iterable[Record]) -> list[Record]:
    """The records of runs that finished (status "ok"), in order."""
    return [r for r in records if r.get("status") == "ok"]


def shape_name(rec: Record) -> str:
    """The record's shape name ("None" where it has none)."""
    return str((rec.get("shape") or {}).get("name"))


def chamfer_l2(rec: Record) -> float:
    """The record's chamfer L2 (squared distances, raw: not ×10³; unit-cube frame), NaN where absent."""
    return by_name()["chamfer_l2"].read(rec)
