"""python -m ddfbench.zero_level RESULTS/<experiment> --out DIR [--n-points N] [--model M ...] [--threads N]

Where a finished SDF run's zero level lies against the true surface, from what the run saved (its
model.pt and gt_mesh.ply): is its error a shift of the whole surface (a bias that one level fixes) or a
spread about it? For every ok run of a family answering sphere tracing with a signed field
(models._sdf_family.SDFFamily: neural_sdf, gan_sdf, grid_sdf), at N points sampled on the GT mesh
(seeded by the record's seed):

- value: the field there, in unit-cube units; offset = value / |gradient| there, the first-order signed
  distance from the GT surface to the learned zero level along the field's normal (> 0: the learned
  surface lies inside the true one). Percentiles 5/25/50/75/95 of the offset and its mean |offset|.
- The run's mesh extracted again at the level of the median value (the same resolution and extraction
  options as the run's), against the GT mesh at the record's point count, radii and seed, beside the
  record's own final metrics at level 0.

DIR gets table.md (its first line: the command, the records' code commits, the measuring code's) and
table.csv, one row per run. The records are not changed. A run whose artifacts cannot be read, or that
is not an SDF family, gets one line on stderr naming its folder; the others are still written (exit 1
when a run could not be read).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from typing import Any

import numpy as np
import pandas as pd
import torch
import trimesh

from ddfbench.errors import InputError
from ddfbench.geometry import BOX_HALF
from ddfbench.metrics import geometry_metrics
from ddfbench.models import load_family
from ddfbench.models._sdf_family import SDFFamily
from ddfbench.reevaluate import artifact
from ddfbench.runs import code_commits, code_sha, find_records

PERCENTILES = (5, 25, 50, 75, 95)
GRAD_BATCH = 4096  # points per backward pass


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


def zero_level_row(rec: dict[str, Any], n_points: int) -> dict[str, Any]:
    """One run's row: its zero level's offsets on the GT surface and its metrics at level 0 and at the median value.
    Raises InputError for a run that is not an SDF family."""
    cfg, ev = rec["config"], rec["config"].get("eval") or {}
    rep = load_family(rec["family"]).load(artifact(rec, "model"), domain=float(cfg.get("domain", BOX_HALF)))
    if not isinstance(rep, SDFFamily):
        raise InputError(f"{rec['_dir']}: family {rec['family']} has no signed field (not an SDF family)")
    gt = trimesh.load(artifact(rec, "gt_mesh"), force="mesh", process=False)
    seed = int(cfg.get("seed", 0))
    points, _ = trimesh.sample.sample_surface(gt, n_points, seed=seed)
    value, slope = value_and_slope(rep, points)
    offset = value / np.maximum(slope, 1e-12)
    level = float(np.median(value))
    radii = [float(r) for r in ev["radii"]]
    shifted = geometry_metrics(gt, rep.to_mesh(int(ev["mesh_resolution"]), level=level), int(ev["n_points"]), radii,
                               seed=seed, noise_floor=False, with_point_to_surface=False)
    row: dict[str, Any] = {"model": rec["model"], "shape": rec["shape"]["name"],
                           "capacity": str(cfg.get("capacity") or ""), "seed": seed, "key": rec["key"],
                           "n_points": n_points, "median_slope": float(np.median(slope)),
                           **{f"offset_p{q}": float(v) for q, v in zip(PERCENTILES, np.percentile(offset, PERCENTILES))},
                           "offset_mean_abs": float(np.abs(offset).mean()), "level": level}
    for name, metrics in (("at_0", rec.get("metrics") or {}), ("at_level", shifted)):
        row[f"chamfer_l2_{name}"] = float(metrics.get("chamfer_l2", math.nan))
        row.update({f"fscore@{r}_{name}": float((metrics.get("fscore") or {}).get(str(r), math.nan)) for r in radii})
    return row


def to_markdown(rows: list[dict[str, Any]]) -> str:
    """The per-run table: offsets ×10³ (unit-cube units), the median level and CD-L2 ×10³ / F@0.01 at both levels."""
    lines = ["| model | shape | capacity | seed | offset ×10³ p5 / p25 / p50 / p75 / p95 | mean abs offset ×10³ | median slope "
             "| level ×10³ | CD-L2 ×10³ at 0 → at level | F@0.01 at 0 → at level |", "|---" * 10 + "|"]
    for r in rows:
        offs = " / ".join(f"{r[f'offset_p{q}'] * 1e3:.3g}" for q in PERCENTILES)
        lines.append(f"| {r['model']} | {r['shape']} | {r['capacity'] or '–'} | {r['seed']} | {offs} | {r['offset_mean_abs'] * 1e3:.3g} "
                     f"| {r['median_slope']:.3g} | {r['level'] * 1e3:.3g} "
                     f"| {r['chamfer_l2_at_0'] * 1e3:.4g} → {r['chamfer_l2_at_level'] * 1e3:.4g} "
                     f"| {r.get('fscore@0.01_at_0', math.nan):.3g} → {r.get('fscore@0.01_at_level', math.nan):.3g} |")
    lines += ["", "offset: the field's value at a point sampled on the GT surface over its gradient's norm there, a "
              "first-order signed distance to the learned zero level (> 0: the learned surface lies inside the true "
              "one); level: the median field value on the GT surface, the level the mesh was extracted at again "
              "(same resolution and options as the run's); 'at 0' is the record's own final result."]
    return "\n".join(lines) + "\n"


def _table_order(rec: dict[str, Any]) -> tuple:
    cfg = rec["config"]
    return rec["model"], rec["shape"]["name"], str(cfg.get("capacity") or ""), int(cfg.get("seed", 0)), rec["key"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ddfbench.zero_level",
                                 description="Where finished SDF runs' zero levels lie against the true surface.")
    ap.add_argument("results", help="an experiment's records folder (results/<experiment>)")
    ap.add_argument("--out", required=True, help="folder for table.md and table.csv")
    ap.add_argument("--n-points", type=int, default=20_000, help="points sampled on each GT surface (default 20000)")
    ap.add_argument("--model", nargs="*", default=None, help="only these models (the records' `model` labels)")
    ap.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    args = ap.parse_args(argv)
    try:
        if args.n_points < 1 or args.threads < 0:
            raise InputError(f"--n-points {args.n_points} / --threads {args.threads}: need n-points >= 1, threads >= 0")
        recs = [r for r in find_records(args.results) if r.get("status") == "ok"
                and (not args.model or r.get("model") in args.model)]
        if not recs:
            raise InputError(f"{args.results}: no finished run records" + (f" of {args.model}" if args.model else ""))
    except InputError as err:
        print(f"ddfbench.zero_level: {err}", file=sys.stderr)
        return 2
    if args.threads:
        torch.set_num_threads(args.threads)
    rows, failed = [], 0
    for rec in sorted(recs, key=_table_order):
        try:
            rows.append(zero_level_row(rec, args.n_points))
        except (InputError, OSError, KeyError, ValueError) as err:
            failed += 1
            print(f"ddfbench.zero_level: {rec['_dir']}: {type(err).__name__}: {str(err).splitlines()[0]}",
                  file=sys.stderr, flush=True)
    if rows:
        os.makedirs(args.out, exist_ok=True)
        used = [r for r in recs if r["key"] in {row["key"] for row in rows}]
        command = f"`python -m ddfbench.zero_level {' '.join(argv if argv is not None else sys.argv[1:])}`"
        md = (f"{command}: {len(rows)} runs ({failed} skipped), records of code "
              f"{', '.join(c[:7] for c in code_commits(used))}, measured by code {(code_sha() or 'unknown')[:7]}.\n\n"
              + to_markdown(rows))
        with open(os.path.join(args.out, "table.md"), "w") as fh:
            fh.write(md)
        pd.DataFrame(rows).to_csv(os.path.join(args.out, "table.csv"), index=False)
        print(md, end="")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
