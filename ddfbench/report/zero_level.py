"""python -m ddfbench.report.zero_level RESULTS/<experiment> --out DIR [--n-points N] [--model M ...] [--threads N]

Where a finished SDF run's zero level lies against the true surface, from what the run saved (its
model and gt_mesh.ply): is its error a shift of the whole surface (a bias that one level removes) or a
spread about it? For every ok run of a family answering rays by sphere tracing a signed field
(models._sdf_family.SDFFamily: neural_sdf, gan_sdf, grid_sdf), at N points sampled on the GT mesh
(metrics.sample_surface, seeded by the record's evaluation seed):

- value: the field there (field units: unit-cube units where the field's slope is 1); offset = value /
  |gradient|, the first-order signed distance from the GT surface to the learned zero level along the
  field's normal (> 0: the learned surface lies inside the true one). Percentiles 5/25/50/75/95 and the
  mean |offset| over the points whose gradient is finite and not ~0 (their share: `slope_ok`), and the
  share whose slope is above the extraction's Lipschitz bound (cfg.extract_lipschitz: there a banded
  extraction is not exact).
- The mesh extracted from the loaded model again at level 0 (a control: it should reproduce the
  record's own chamfer; a difference is the sampling noise of a mesh that came out otherwise) and at
  the level of the median value, each with the run's resolution and extraction options, against the
  GT mesh at the record's point count, radii and evaluation seed. The median level is read off the GT surface,
  an answer the representation does not have: its column bounds what one global shift of the level
  could give, it is not a result of the method.

DIR gets table.md (its first line: the command, the records' code commits, the measuring code's) and
table.csv, one row per run, both written from the measured rows saved beside them (ddfbench.report.measured),
from which they regenerate. The records are not changed. Runs of other families are counted and left
out; a run whose artifacts cannot be read gets one line on stderr naming its folder, and the others
are still written (exit 1).
"""

from __future__ import annotations

import math
import os
import sys
import zipfile
from typing import Any

import numpy as np
import pandas as pd
import torch
import trimesh

from ddfbench.core.errors import InputError
from ddfbench.evaluate.metrics import geometry_metrics, sample_surface
from ddfbench.models import load_family
from ddfbench.models._sdf_family import SDFFamily
from ddfbench.report import measured
from ddfbench.report.reevaluate import (
    artifact,
    checked_counts,
    finished_records,
    record_evaluation_seed,
    records_parser,
    saved_model,
    unreadable,
)
from ddfbench.report.tables import pipe_lines
from ddfbench.run.checks import writable_folder

PERCENTILES = (5, 25, 50, 75, 95)
GRAD_BATCH = 1024  # points per backward pass (the GAN generator's graph is ~35k floats a point)
MIN_SLOPE = 1e-6  # a gradient norm below this gives no offset


def value_and_slope(rep: SDFFamily, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(field value (N,), |gradient| (N,)) float64 at points (N, 3) in the normalized frame."""
    vals, slopes = [], []
    for s in range(0, len(points), GRAD_BATCH):
        x = torch.from_numpy(np.asarray(points[s : s + GRAD_BATCH], np.float32)).to(rep.device).requires_grad_(True)
        v = rep.field(x).reshape(-1)
        (g,) = torch.autograd.grad(v.sum(), x)
        vals.append(v.detach().double().cpu().numpy())
        slopes.append(g.detach().double().norm(dim=1).cpu().numpy())
    return np.concatenate(vals), np.concatenate(slopes)


def offsets(value: np.ndarray, slope: np.ndarray) -> np.ndarray:
    """value / slope (N,), NaN where the slope is not finite or below MIN_SLOPE (no first-order distance)."""
    ok = np.isfinite(slope) & (slope >= MIN_SLOPE) & np.isfinite(value)
    return np.where(ok, value / np.where(ok, slope, 1.0), np.nan)


def _mesh_metrics(rep: SDFFamily, gt: trimesh.Trimesh, level: float, ev: dict[str, Any], seed: int) -> dict[str, Any]:
    """chamfer_l2, fscore@r, empty, capped of the mesh of the field's `level` set (the run's eval settings)."""
    radii = [float(r) for r in ev["radii"]]
    m = geometry_metrics(gt, rep.to_mesh(int(ev["mesh_resolution"]), level=level), int(ev["n_points"]), radii,
                         seed=seed, noise_floor=False, with_point_to_surface=False)
    info = getattr(rep, "extract_info", {}) or {}
    return {"chamfer_l2": float(m["chamfer_l2"]), **{f"fscore@{r}": float(m["fscore"][str(r)]) for r in radii},
            "empty": bool(info.get("empty", False)), "capped": bool(info.get("capped", False))}


def zero_level_row(rec: dict[str, Any], n_points: int) -> dict[str, Any]:
    """One SDF run's row: its zero level's offsets on the GT surface, and its metrics at level 0 (the record's
    and recomputed) and at the median value."""
    cfg, ev = rec["config"], rec["config"].get("eval") or {}
    rep = saved_model(rec)
    gt = trimesh.load(artifact(rec, "gt_mesh"), force="mesh", process=False)
    seed, eval_seed = int(cfg.get("seed", 0)), record_evaluation_seed(rec)
    value, slope = value_and_slope(rep, sample_surface(gt, n_points, eval_seed)[0])
    off = offsets(value, slope)
    level = float(np.nanmedian(value)) if np.isfinite(value).any() else math.nan
    lipschitz = float((rep.cfg or {}).get("extract_lipschitz", 1.0))
    row: dict[str, Any] = {"model": rec["model"], "shape": rec["shape"]["name"],
                           "capacity": str(cfg.get("capacity") or ""), "seed": seed, "key": rec["key"],
                           "n_points": n_points, "slope_ok": float(np.isfinite(off).mean()),
                           "median_slope": float(np.nanmedian(slope)), "over_lipschitz": float((slope > lipschitz).mean()),
                           **{f"offset_p{q}": float(v) for q, v in zip(PERCENTILES, np.nanpercentile(off, PERCENTILES))},
                           "offset_mean_abs": float(np.nanmean(np.abs(off))), "level": level,
                           "chamfer_l2_record": float((rec.get("metrics") or {}).get("chamfer_l2", math.nan))}
    for name, lv in (("at_0", 0.0), ("at_level", level)):
        row.update({f"{k}_{name}": v for k, v in _mesh_metrics(rep, gt, lv, ev, eval_seed).items()})
    return row


def to_markdown(rows: list[dict[str, Any]]) -> str:
    """The per-run table: offsets ×10³ (unit-cube units), the median level, and CD-L2 ×10³ / F@0.01 at each level."""
    cells = []
    for r in rows:
        offs = " / ".join(f"{r[f'offset_p{q}'] * 1e3:.3g}" for q in PERCENTILES)
        flags = "".join(f" ({what} at level)" for what in ("empty", "capped") if r[f"{what}_at_level"])
        cells.append([f"{r['model']}", f"{r['shape']}", f"{r['capacity'] or '–'}", f"{r['seed']}", offs,
                      f"{r['offset_mean_abs'] * 1e3:.3g}", f"{r['median_slope']:.3g}", f"{r['level'] * 1e3:.3g}",
                      f"{r['chamfer_l2_record'] * 1e3:.4g} / {r['chamfer_l2_at_0'] * 1e3:.4g} / "
                      f"{r['chamfer_l2_at_level'] * 1e3:.4g}{flags}",
                      f"{r.get('fscore@0.01_at_0', math.nan):.3g} → {r.get('fscore@0.01_at_level', math.nan):.3g}"])
    lines = pipe_lines(["model", "shape", "capacity", "seed", "offset ×10³ p5 / p25 / p50 / p75 / p95",
                        "mean abs offset ×10³", "median slope", "level ×10³",
                        "CD-L2 ×10³ record / at 0 / at level", "F@0.01 at 0 → at level"], cells)
    lines += ["", "offset: the field's value at a point sampled on the GT surface over its gradient's norm there, a "
              "first-order signed distance to the learned zero level (> 0: the learned surface lies inside the true "
              "one). level: the median field value on the GT surface. 'record' is the run's own result; 'at 0' the "
              "same extraction from the saved model again (a control); 'at level' the mesh extracted at the median "
              "level with the same resolution and options. That level is read off the GT surface, which the "
              "representation does not have: it bounds what one global shift could give and is not a result of "
              "the method. table.csv adds every F-score radius, the share of points with a usable gradient "
              "(slope_ok) and with a slope above the extraction's Lipschitz bound (over_lipschitz)."]
    return "\n".join(lines) + "\n"


def write_tables(out: str, head: dict[str, str], rows: list[dict[str, Any]]) -> str:
    """table.md (measured.first_line, then to_markdown) and table.csv (the rows, one per run) into out; table.md's
    text."""
    md = measured.first_line(head) + "\n\n" + to_markdown(rows)
    with open(os.path.join(out, "table.md"), "w") as fh:
        fh.write(md)
    pd.DataFrame(rows).to_csv(os.path.join(out, "table.csv"), index=False)
    return md


def _table_order(rec: dict[str, Any]) -> tuple:
    cfg = rec["config"]
    return rec["model"], rec["shape"]["name"], str(cfg.get("capacity") or ""), int(cfg.get("seed", 0)), rec["key"]


def main(argv: list[str] | None = None) -> int:
    ap = records_parser("zero_level", "Where finished SDF runs' zero levels lie against the true surface.",
                        "table.md and table.csv", 20_000)
    args = ap.parse_args(argv)
    try:
        checked_counts(args)
        recs = finished_records(args.results, args.model)
        sdf_recs = [r for r in recs if issubclass(load_family(str(r["family"])), SDFFamily)]
        if not sdf_recs:
            raise InputError(f"{args.results}: none of its {len(recs)} finished runs is of an SDF family")
        writable_folder(args.out, "--out ")
    except InputError as err:
        print(f"ddfbench.report.zero_level: {err}", file=sys.stderr)
        return 2
    rows, failed = [], 0
    for rec in sorted(sdf_recs, key=_table_order):
        try:
            rows.append(zero_level_row(rec, args.n_points))
        except (InputError, OSError, KeyError, ValueError, RuntimeError, zipfile.BadZipFile) as err:
            failed += 1
            unreadable("zero_level", rec, err)
    if rows:
        used = [r for r in sdf_recs if r["key"] in {row["key"] for row in rows}]
        other = len(recs) - len(sdf_recs)
        head = measured.header("zero_level", argv, f"{len(rows)} SDF runs ({failed} unreadable, {other} of other "
                               "families left out)", used, args.results)
        return measured.publish("zero_level", args.out, head, rows, failed)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
