"""python -m ddfbench.report.edge_error RESULTS/<experiment> --out DIR [--model M ...] [--jump T]

Where a finished run's image error lies: at the edges of the picture (silhouettes and the steps where
one part of the shape hides another, where the depth along a ray jumps) or across the surface. It
reads the renders each run saved (renders/cam<c>_{depth,mask}.npy and their _reference twins: the
family's frames and the oracle's, from the same cameras), so nothing is evaluated again.

Edge pixels are those of the oracle's frame: both pixels of every 4-neighbour pair whose masks differ
or whose depths, where both hit, differ by more than `jump` (unit-cube units, default 0.1: above the
step between neighbours on a surface seen at grazing incidence at the scenes' pixel footprint, ~0.015
at 96² from the orbit radius 2). A pixel's band is its distance in pixels to the nearest edge pixel
(exact Euclidean): edge (0), near (≤ 2), mid (≤ 4), far (> 4; also every pixel of a frame without
edges). Per band, summed over a run's cameras:

- pixels: those either render hits (the union of the masks);
- mask_errors: those exactly one render hits (1 − mask IoU = mask_errors / pixels over all bands);
- both: those both hit; abs_depth: the sum of |t − t_ref| over them (unit-cube units).

DIR gets table.md (its first line: the command, the records' code commits, the measuring code's; one
row per model, shape and capacity, mean ± std over seeds) and table.csv (one row per run and band), both
written from the measured rows saved beside them (ddfbench.report.measured), from which they regenerate.
The records are not changed. A run without depth and mask renders gets one line on stderr naming its
folder; the others are still written (exit 1).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from typing import Any

import numpy as np
import pandas as pd
from scipy import ndimage

from ddfbench.core.errors import InputError
from ddfbench.report import measured
from ddfbench.report.records import no_result
from ddfbench.report.reevaluate import artifact, finished_records, unreadable
from ddfbench.report.stats import summarize_values, within_range
from ddfbench.report.tables import NOT_CONVERGED, pipe_lines
from ddfbench.run.checks import writable_folder

BANDS = (("edge", 0.0), ("near", 2.0), ("mid", 4.0), ("far", math.inf))  # name, largest distance (px)
NEAR = ("edge", "near")  # the bands within 2 px of an edge
JUMP = 0.1  # unit-cube units
COUNTS = ("pixels", "mask_errors", "both", "abs_depth")


def edge_pixels(depth: np.ndarray, mask: np.ndarray, jump: float) -> np.ndarray:
    """(H, W) bool: the edge pixels of one frame, depth (H, W) float (inf on background), mask (H, W) bool."""
    edges = np.zeros(mask.shape, bool)
    depth = np.where(mask, depth, 0.0)
    for axis in (0, 1):
        lo = [slice(None)] * 2
        hi = [slice(None)] * 2
        lo[axis], hi[axis] = slice(None, -1), slice(1, None)
        lo_t, hi_t = tuple(lo), tuple(hi)
        both = mask[lo_t] & mask[hi_t]
        differ = (mask[lo_t] != mask[hi_t]) | (both & (np.abs(depth[lo_t] - depth[hi_t]) > jump))
        edges[lo_t] |= differ
        edges[hi_t] |= differ
    return edges


def bands(edges: np.ndarray) -> np.ndarray:
    """(H, W) int: each pixel's band (an index into BANDS) by its distance in pixels to the nearest edge pixel."""
    if not edges.any():
        return np.full(edges.shape, len(BANDS) - 1)
    distance = ndimage.distance_transform_edt(~edges)
    return np.searchsorted([limit for _, limit in BANDS], distance, side="left")


def band_counts(depth: np.ndarray, mask: np.ndarray, ref_depth: np.ndarray, ref_mask: np.ndarray,
                jump: float) -> dict[str, np.ndarray]:
    """COUNTS (module docstring) per band, each (len(BANDS),), of one frame against the oracle's; arrays (H, W)."""
    band = bands(edge_pixels(ref_depth, ref_mask, jump)).ravel()
    both = mask & ref_mask
    err = np.where(both, np.abs(np.where(mask, depth, 0.0) - np.where(ref_mask, ref_depth, 0.0)), 0.0)
    n = len(BANDS)
    return {name: np.bincount(band, weights.ravel(), n) for name, weights in
            (("pixels", mask | ref_mask), ("mask_errors", mask ^ ref_mask), ("both", both), ("abs_depth", err))}


def _frame(folder: str, camera: int, reference: bool) -> tuple[np.ndarray, np.ndarray]:
    """(depth (H, W) float32, inf on background; mask (H, W) bool) of one camera, the oracle's if `reference`."""
    suffix = "_reference" if reference else ""
    depth, mask = (os.path.join(folder, f"cam{camera}_{what}{suffix}.npy") for what in ("depth", "mask"))
    for path in (depth, mask):
        if not os.path.exists(path):
            raise InputError(f"{path}: missing (the run's scene saved no depth and mask renders)")
    return np.load(depth), np.load(mask).astype(bool)


def run_counts(rec: dict[str, Any], jump: float) -> dict[str, np.ndarray]:
    """COUNTS per band summed over the run's cameras, from its saved renders."""
    folder = artifact(rec, "renders")
    cameras = sorted(int(name[3:].split("_")[0]) for name in os.listdir(folder)
                     if name.startswith("cam") and name.endswith("_depth_reference.npy"))
    if not cameras:
        raise InputError(f"{folder}: no cam<c>_depth_reference.npy (the run's scene saved no depth renders)")
    asked = ((((rec.get("config") or {}).get("scene") or {}).get("cameras") or {}).get("n"))
    if isinstance(asked, int) and len(cameras) < asked:  # a camera's renders lost: its run is not measured in part
        raise InputError(f"{folder}: depth renders of {len(cameras)} of the scene's {asked} cameras")
    total = {k: np.zeros(len(BANDS)) for k in COUNTS}
    for c in cameras:
        for k, v in band_counts(*_frame(folder, c, False), *_frame(folder, c, True), jump).items():
            total[k] += v
    return total


def _ratio(num: float, den: float) -> float:
    return num / den if den else math.nan


def figures(counts: dict[str, np.ndarray]) -> dict[str, float]:
    """A run's summary from its band counts: the shares (0-1) of pixels, of mask errors and of summed depth
    error within 2 px of an edge; the depth MAE (unit-cube units) there, beyond 4 px and overall (NaN where
    no pixel of that set is hit by both); the mask IoU (1 where neither render hits)."""
    near = [i for i, (name, _) in enumerate(BANDS) if name in NEAR]
    far = len(BANDS) - 1
    total = {k: float(v.sum()) for k, v in counts.items()}
    return {
        "pixels_near": _ratio(counts["pixels"][near].sum(), total["pixels"]),
        "mask_errors_near": _ratio(counts["mask_errors"][near].sum(), total["mask_errors"]),
        "abs_depth_near": _ratio(counts["abs_depth"][near].sum(), total["abs_depth"]),
        "depth_mae_near": _ratio(counts["abs_depth"][near].sum(), counts["both"][near].sum()),
        "depth_mae_far": _ratio(counts["abs_depth"][far], counts["both"][far]),
        "depth_mae": _ratio(total["abs_depth"], total["both"]),
        "mask_iou": 1.0 - _ratio(total["mask_errors"], total["pixels"]) if total["pixels"] else 1.0,
    }


def _label(rec: dict[str, Any]) -> tuple[str, str, str, int]:
    """model, shape, capacity level ("–" without one) and seed of a record."""
    cfg = rec.get("config") or {}
    return (str(rec.get("model")), str((rec.get("shape") or {}).get("name")), str(cfg.get("capacity") or "–"),
            int(cfg.get("seed", 0)))


COLUMNS = (("pixels_near", "pixels ≤ 2 px of an edge %", 100), ("mask_errors_near", "mask errors ≤ 2 px %", 100),
           ("abs_depth_near", "summed depth error ≤ 2 px %", 100), ("depth_mae_near", "depth MAE ≤ 2 px ×10³", 1e3),
           ("depth_mae_far", "depth MAE > 4 px ×10³", 1e3), ("depth_mae", "depth MAE ×10³", 1e3),
           ("mask_iou", "mask IoU", 1))


def _cell(values: pd.Series, key: str, scale: float, runs: int) -> str:
    """mean ± std [95 % t interval, cut to the figure's range] of the finite values, scaled; "(n = k)" where k < runs
    are finite."""
    s = within_range(summarize_values(values), key, (0.0, 1.0) if scale == 100 else None)  # shares print as %
    if s.n == 0:
        return "–"
    text = f"{s.mean * scale:.3g}"
    if s.n > 1:
        std = s.std if s.std > 1e-9 * abs(s.mean) else 0.0  # float noise of identical runs prints as 0
        text += f" ± {std * scale:.2g} [{s.lo * scale:.3g}, {s.hi * scale:.3g}]"
    return text + (f" (n = {s.n})" if s.n < runs else "")


def to_markdown(runs: pd.DataFrame) -> str:
    """One row per model, shape and capacity: each figure's mean ± std [95 % t interval] over the runs (seeds), n."""
    rows = []
    for (model, shape, capacity), group in runs.groupby(["model", "shape", "capacity"], sort=True):
        cells = [_cell(group[key], key, scale, len(group)) for key, _, scale in COLUMNS]
        n = f"{len(group)} {NOT_CONVERGED}" if group["no_result"].all() else str(len(group))
        rows.append([f"{model}", f"{shape}", f"{capacity}", n, *cells])
    lines = pipe_lines(["model", "shape", "capacity", "n", *(title for _, title, _ in COLUMNS)], rows)
    lines += ["", "An edge pixel is one of the oracle's frame where the hit mask changes or the depth jumps (module "
              "docstring of ddfbench/report/edge_error.py); '≤ 2 px': within 2 pixels of one. 'mask errors': pixels exactly one "
              "render hits; 'summed depth error': Σ|t − t_ref| over the pixels both hit. depth MAE and mask IoU over all "
              "pixels are the record's own image metrics, computed again (a control). Mean ± std [95 % t interval of the "
              "mean, cut to the figure's range] over seeds; '(n = k)': only k of the row's runs define the figure (the others hit no such pixel); "
              f"'{NOT_CONVERGED}': every run's mesh was empty or off the shape, not a method result."]
    return "\n".join(lines) + "\n"


def write_tables(out: str, head: dict[str, str], rows: list[dict[str, Any]]) -> str:
    """table.csv (the rows: one per run and band) and table.md (measured.first_line, then to_markdown) into out;
    table.md's text."""
    table = pd.DataFrame(rows)
    table.to_csv(os.path.join(out, "table.csv"), index=False)
    md = measured.first_line(head) + "\n\n" + to_markdown(table.drop_duplicates("key"))
    with open(os.path.join(out, "table.md"), "w") as fh:
        fh.write(md)
    return md


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ddfbench.report.edge_error",
                                 description="Where finished runs' depth and mask errors lie: at the picture's edges or across the surface.")
    ap.add_argument("results", help="an experiment's records folder (results/<experiment>)")
    ap.add_argument("--out", required=True, help="folder for table.md and table.csv")
    ap.add_argument("--model", nargs="*", default=None, help="only these models (the records' `model` labels)")
    ap.add_argument("--jump", type=float, default=JUMP, help=f"a depth step that makes an edge, unit-cube units (default {JUMP})")
    args = ap.parse_args(argv)
    try:
        if not args.jump > 0:
            raise InputError(f"--jump {args.jump}: must be > 0 (unit-cube units)")
        recs = finished_records(args.results, args.model)
        writable_folder(args.out, "--out ")
    except InputError as err:
        print(f"ddfbench.report.edge_error: {err}", file=sys.stderr)
        return 2
    rows, used, failed = [], [], 0
    for rec in sorted(recs, key=lambda r: (*_label(r), str(r.get("key")))):
        try:
            counts = run_counts(rec, args.jump)
        except (InputError, OSError, ValueError) as err:
            failed += 1
            unreadable("edge_error", rec, err)
            continue
        used.append(rec)
        run = {**dict(zip(("model", "shape", "capacity", "seed"), _label(rec))), "key": rec["key"],
               "no_result": no_result(rec), **figures(counts)}
        rows += [{**run, "band": name, **{k: float(counts[k][i]) for k in COUNTS}} for i, (name, _) in enumerate(BANDS)]
    if not rows:
        print(f"ddfbench.report.edge_error: none of the {len(recs)} finished runs has readable renders; nothing written",
              file=sys.stderr)
        return 1
    head = measured.header("edge_error", argv, f"{len(used)} runs' saved renders ({failed} unreadable), edges at "
                           f"depth steps > {args.jump:g}", used, args.results)
    return measured.publish("edge_error", args.out, head, rows, failed)


if __name__ == "__main__":
    sys.exit(main())
