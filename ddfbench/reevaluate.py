"""python -m ddfbench.reevaluate RESULTS/<experiment> --out DIR [--n-points N] [--scene NAME] [--model M ...]
                                [--threads N]

The finished runs of an experiment measured again at other evaluation settings, from what each run
saved: its reconstruction (reconstruction.ply) against its GT mesh (gt_mesh.ply) at N surface points
per mesh, and, with --scene, its saved model rendered with conf/scene/<NAME>.yaml against the mesh's
BVH. A sweep whose probes needed a small point count (convergence: 20k) is so compared with targets
stated at the 100k points of every other experiment, and gets image metrics it did not render,
without refitting. The records are not changed; DIR gets reevaluated.csv (a row per run) and
reevaluated.md (mean ± std, n and the t interval over seeds per model and shape).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from typing import Any, Sequence

import pandas as pd
import torch
import trimesh

from ddfbench import plugins
from ddfbench.errors import InputError
from ddfbench.geometry import BOX_HALF
from ddfbench.metrics import geometry_metrics
from ddfbench.models import load_family
from ddfbench.oracle import Oracle
from ddfbench.report.stats import INTERVAL_NAME, summarize_values
from ddfbench.representation import Budget, FitData
from ddfbench.runs import find_records

# (column, label) of the summary; chamfer and depth in ×10³ as every report shows them
SHOWN = (("chamfer_l2", "CD-L2 ×10³", 1e3), ("p2s_chamfer_l2", "p2s CD-L2 ×10³", 1e3), ("f@0.01", "F@0.01", 1.0),
         ("floor_chamfer_l2", "floor CD-L2 ×10³", 1e3), ("floor_f@0.01", "floor F@0.01", 1.0),
         ("mask_iou", "mask IoU", 1.0), ("depth_mae", "depth MAE ×10³", 1e3))


def _mesh(path: str) -> trimesh.Trimesh:
    if not os.path.isfile(path):
        return trimesh.Trimesh()  # no reconstruction.ply: the run's mesh was empty
    return trimesh.load(path, force="mesh", process=False)


def evaluate_run(rec: dict[str, Any], n_points: int, radii: Sequence[float], scene: dict | None) -> dict[str, Any]:
    """One run's row: its labels and the geometry (and, with a scene, image) metrics at these settings."""
    folder, cfg = rec["_dir"], rec["config"]
    seed = int(cfg.get("seed", 0))
    gt = _mesh(os.path.join(folder, rec["artifacts"]["gt_mesh"]))
    rec_mesh = _mesh(os.path.join(folder, rec["artifacts"].get("reconstruction") or "reconstruction.ply"))
    m = geometry_metrics(gt, rec_mesh, n_points, radii, seed=seed)
    row = {"key": rec["key"], "model": rec["model"], "shape": rec["shape"]["name"], "seed": seed,
           "n_points": n_points, "empty": bool(m["empty_reconstruction"]), "chamfer_l2": m["chamfer_l2"],
           "p2s_chamfer_l2": m.get("p2s_chamfer_l2"),
           **{f"f@{r:g}": m["fscore"][f"{r:g}"] for r in radii},
           "floor_chamfer_l2": m["noise_floor"]["chamfer_l2"], "floor_f@0.01": m["noise_floor"]["fscore"]["0.01"]}
    if scene is not None:
        from ddfbench.render import render_scene

        domain = float(cfg.get("domain", BOX_HALF))
        rep = load_family(rec["family"]).load(os.path.join(folder, rec["artifacts"]["model"]), domain=domain)
        reference = load_family("mesh")({"faces": 0}, domain=domain)
        reference.fit(FitData(samples=None, mesh=gt, oracle=Oracle(gt)), Budget(max_steps=1, max_seconds=1.0))
        with tempfile.TemporaryDirectory(prefix="ddfbench-reeval-") as tmp:
            image = render_scene(rep, reference, scene, tmp, seed)["metrics"]
        row.update(mask_iou=image.get("mask_iou"), depth_mae=image.get("depth_mae"))
    return row


def summary(rows: pd.DataFrame) -> str:
    """Markdown: mean ± std (n) per model and shape, the t interval beside each."""
    cols = [(c, label, scale) for c, label, scale in SHOWN if c in rows and rows[c].notna().any()]
    lines = ["| model | shape | n (empty) | " + " | ".join(label for _, label, _ in cols) + " |",
             "|---|---|---|" + "---|" * len(cols)]
    for (model, shape), g in rows.groupby(["model", "shape"], sort=True):
        cells = []
        for c, _, scale in cols:
            s = summarize_values(g.loc[~g["empty"], c] if not c.startswith("floor") else g[c])
            cells.append(f"{s.mean * scale:.4g} ± {s.std * scale:.2g} [{s.lo * scale:.4g}, {s.hi * scale:.4g}]"
                         if s.n > 1 else (f"{s.mean * scale:.4g}" if s.n else "–"))
        lines.append(f"| {model} | {shape} | {len(g)} ({int(g['empty'].sum())}) | " + " | ".join(cells) + " |")
    return "\n".join(lines) + (f"\n\nmean ± std [{INTERVAL_NAME}] over the non-empty runs; the floor columns are "
                               "GT against an independent resample of GT at the same point count.\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ddfbench.reevaluate", description=__doc__.splitlines()[0])
    ap.add_argument("results", help="an experiment's records folder (results/<experiment>)")
    ap.add_argument("--out", required=True, help="folder for reevaluated.csv and reevaluated.md")
    ap.add_argument("--n-points", type=int, default=100_000, help="surface points per mesh (default 100000)")
    ap.add_argument("--scene", default=None, help="also render each saved model with conf/scene/<NAME>.yaml")
    ap.add_argument("--model", nargs="*", default=None, help="only these models (the records' `model` labels)")
    ap.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    args = ap.parse_args(argv)
    if args.threads > 0:
        torch.set_num_threads(args.threads)
    try:
        if args.n_points < 1:
            raise InputError(f"--n-points {args.n_points}: must be >= 1")
        scene = plugins.plugin_yaml("scene", args.scene) if args.scene else None
        radii = [float(r) for r in plugins.plugin_yaml("eval", "default")["radii"]]
        recs = [r for r in find_records(args.results) if r.get("status") == "ok"
                and (not args.model or r.get("model") in args.model)]
        if not recs:
            raise InputError(f"{args.results}: no finished run records" + (f" of {args.model}" if args.model else ""))
    except InputError as err:
        print(f"ddfbench.reevaluate: {err}", file=sys.stderr)
        return 2
    rows = []
    for i, rec in enumerate(sorted(recs, key=lambda r: (r["model"], r["shape"]["name"], r["config"].get("seed", 0)))):
        rows.append(evaluate_run(rec, args.n_points, radii, scene))
        print(f"[{i + 1}/{len(recs)}] {rec['model']} {rec['shape']['name']} seed {rows[-1]['seed']}: "
              f"CD-L2 {rows[-1]['chamfer_l2']:.4g}", file=sys.stderr, flush=True)
    df = pd.DataFrame(rows)
    os.makedirs(args.out, exist_ok=True)
    df.to_csv(os.path.join(args.out, "reevaluated.csv"), index=False)
    text = (f"`python -m ddfbench.reevaluate {' '.join(argv if argv is not None else sys.argv[1:])}`\n\n"
            + summary(df))
    with open(os.path.join(args.out, "reevaluated.md"), "w") as fh:
        fh.write(text)
    print(text, end="")
    return 0


if __name__ == "__main__":
    sys.exit(main())
