"""Run records as the report modules read them.

A record is the dict one run writes to <out_dir>/<experiment>/<key>/record.json (ddfbench.run.runs):
status ("ok" | "failed"), model (the preset label), shape {"name"}, config (the semantic config,
seed included), metrics (chamfer_l2, fscore, noise_floor, ...), cost (fit_s, render_warm_s, ...),
sampling, fit (steps, probes, ...). Values may be missing, None, or a string such as "inf" (the
writer's strict JSON). These helpers read the fields every report module needs: which runs
finished, the shape, a number, and the chamfer L2 (through ddfbench.evaluate.metric_registry).
"""

from __future__ import annotations

import functools
import math
import os
from typing import Any, Iterable

from ddfbench.evaluate.metric_registry import FSCORE_RADII, as_float, by_name

__all__ = ["OFF_SHAPE_RULE", "Record", "WIDEST_F", "as_float", "at_largest_image", "chamfer_l2",
           "distinct_shape_names", "empty_mesh", "family_class", "no_result", "off_shape", "ok_records", "shape_name"]

WIDEST_F = f"fscore@{max(FSCORE_RADII)}"  # 0 there: no sampled point of either surface near the other
OFF_SHAPE_RULE = f"{by_name()[WIDEST_F].label} = 0"  # as the reports write it
SURFACE_FACTORS = ("s_fc", "s_dr", "s_p")  # the DDF paper's surface-sampling factors, as a sweep's keys

Record = dict[str, Any]


def ok_records(records: Iterable[Record]) -> list[Record]:
    """The records of runs that finished (status "ok"), in order."""
    return [r for r in records if r.get("status") == "ok"]


def shape_name(rec: Record) -> str:
    """The record's shape name ("None" where it has none)."""
    return str((rec.get("shape") or {}).get("name"))


@functools.cache
def family_class(family: str) -> Any:
    """The Representation class of a record's `family` in this checkout, None where it has no such family."""
    from ddfbench.models import available_families, load_family  # the families import torch: only when asked

    return load_family(family) if family in available_families() else None


def _file_of(rec: Record) -> str | None:
    """The mesh file a record's shape was read from (`shape=file shape.path=...`), None for a catalog shape."""
    shape = (rec.get("config") or {}).get("shape") or {}
    return str(shape.get("path")) if shape.get("name") == "file" and shape.get("path") else None


def distinct_shape_names(records: list[Record]) -> list[Record]:
    """The records with one geometry to each shape name. A file's shape is named by its file name without the
    extension, so files of one name in several folders (ShapeNet's model_normalized.obj) or a file named like a
    catalog shape (torus.obj beside `torus`) would share a name, and with it a noise-floor row, "best" marks and a
    mean over shapes. Each such file is named instead by the shortest ending of its path that tells them apart
    (`a/model`, `myshapes/torus`); catalog shapes keep their names. A renamed record is a new dict."""
    sources: dict[str, set[str | None]] = {}
    for rec in records:
        sources.setdefault(shape_name(rec), set()).add(_file_of(rec))
    label: dict[str, str] = {}
    for name, found in sources.items():
        files = sorted(f for f in found if f is not None)
        if len(found) < 2 or not files:
            continue
        parts = {f: os.path.splitext(os.path.normpath(f))[0].split(os.sep) for f in files}
        for depth in range(2, max(len(p) for p in parts.values()) + 1):
            ends = {f: "/".join(p[-depth:]) for f, p in parts.items()}
            if len(set(ends.values())) == len(files) and not set(ends.values()) & set(sources):
                break
        else:  # a bare file name beside a catalog shape of that name
            ends = {f: f"{'/'.join(p)} (file)" for f, p in parts.items()}
        label.update(ends)
    return [{**rec, "shape": {**rec["shape"], "name": label[_file_of(rec)]}} if _file_of(rec) in label else rec
            for rec in records]


def chamfer_l2(rec: Record) -> float:
    """The record's chamfer L2 (squared distances, raw: not ×10³; unit-cube frame), NaN where absent."""
    return by_name()["chamfer_l2"].read(rec)


def empty_mesh(rec: Record) -> bool:
    """Whether the run's reconstruction was empty (its metrics are the defined penalty)."""
    return bool((rec.get("metrics") or {}).get("empty_reconstruction"))


def off_shape(rec: Record) -> bool:
    """Whether the run's reconstruction is not empty but shares no surface with the ground truth: its F-score
    at the widest radius is 0, i.e. no sampled point of either surface lies within that distance of the other
    (a fit that never found the shape). It depends on the samples: one sampled point near the shape makes
    the run a result. A record without that F-score (or NaN) is not judged (False)."""
    f = by_name()[WIDEST_F].read(rec)
    return not empty_mesh(rec) and math.isfinite(f) and f == 0.0


def no_result(rec: Record) -> bool:
    """An empty reconstruction or one off the shape: not a method result."""
    return empty_mesh(rec) or off_shape(rec)


NOT_CONVERGED = "not converged"  # a row or cell whose every reconstruction was empty or off the shape


def no_result_label(failed: int, runs: int) -> str:
    """A cell's runs without a result: 'not converged' when every one of them, else 'no result in k of n'."""
    return NOT_CONVERGED if failed == runs else f"no result in {failed} of {runs}"


def at_largest_image(records: Iterable[Record]) -> tuple[int, list[Record]]:
    """(width in pixels, the ok records rendered at the largest image width among them): one frame time per fitted
    model where a sweep rendered each fit at several sizes."""
    ok = ok_records(records)
    width = max(((r.get("scene") or {}).get("width") or 0 for r in ok), default=0)
    return width, [r for r in ok if ((r.get("scene") or {}).get("width") or 0) == width]
