"""The shape suite's report sections: the shapes with their measured tags, each family over shapes, the paired
family ratios (Holm-corrected), and how accuracy moves along each difficulty axis.

Inference is over shapes (ddfbench.report.across_shapes): a family's value on a shape is the mean over its seeds;
a (family, shape) cell with a run that gave no result (an empty mesh or one off the shape) is listed and left out
of the family's summaries and ratios (n says how many shapes remain); "not converged" is kept for a cell whose every
run gave no result, as in the report's main table.

The tags are measured once from the meshes (ddfbench.truth.difficulty) into shapes.csv beside the report and read
from there afterwards, so a rebuild from the compact records needs no mesh.

    python -m ddfbench.report results/shape_suite --out reports/shape_suite     (this module writes its sections)
"""

from __future__ import annotations

import math
import os
from typing import Any, Callable

import numpy as np
import pandas as pd
from scipy import stats as _scipy_stats

from ddfbench.evaluate.metric_registry import by_name
from ddfbench.report.across_shapes import fmt, geometric, ratio, shape_means, share_mean
from ddfbench.report.records import Record, no_result, no_result_label, ok_records, shape_name
from ddfbench.report.stats import holm, welch_ratio
from ddfbench.report.tables import pipe_table
from ddfbench.truth.suite import SUITE_V1

TAGS_FILE = "shapes.csv"
AXES = ("thinnest", "genus", "sharp_edges", "detail", "open_boundary", "components")
AXIS_LABELS = {"thinnest": "thinnest part", "genus": "genus", "sharp_edges": "crease length / sqrt(area)",
               "detail": "detail (p90 curvature)", "open_boundary": "open boundary share", "components": "components"}
# harder is larger on every axis but thinness: a thinner part is harder
HARDER_WHEN_LOW = {"thinnest"}
# (numerator, denominator) of the paired family ratios; a pair missing from the records is left out
PAIRS = (("ddf_tuned", "neural_sdf_tuned"), ("ddf_tuned", "grid_sdf"), ("neural_sdf_tuned", "grid_sdf"),
         ("ddf_tuned", "mesh_lod500"), ("grid_sdf", "mesh_lod500"), ("gan_sdf_tuned", "neural_sdf_tuned"))
CHAMFER, FSCORE = "chamfer_l2", "fscore@0.01"


def measure_tags(names: list[str]) -> pd.DataFrame:
    """One row per shape: split, kind, faces, the difficulty tags, provenance and license (measured now)."""
    from ddfbench.truth.difficulty import difficulty
    from ddfbench.truth.shapes import load_shape

    meta = {s.name: s for s in SUITE_V1}
    rows = []
    for name in names:
        tags = difficulty(load_shape({"name": name}).mesh).as_dict()
        s = meta.get(name)
        rows.append({"shape": name, "split": s.split if s else "", "kind": s.kind if s else "", **tags,
                     "provenance": s.provenance if s else "", "license": s.license if s else ""})
    return pd.DataFrame(rows)


def tags_table(out_dir: str, names: list[str]) -> pd.DataFrame:
    """The tags of `names` from out_dir/shapes.csv, measured (and the file written) when it lacks one of them.
    The file holds every suite shape, so the table in the report shows the tuning shapes too."""
    path = os.path.join(out_dir, TAGS_FILE)
    if os.path.isfile(path):
        df = pd.read_csv(path)
        if set(names) <= set(df["shape"]):
            return df
    wanted = list(dict.fromkeys([s.name for s in SUITE_V1] + list(names)))
    df = measure_tags(wanted)
    df.to_csv(path, index=False, float_format="%.6g")
    return df


def _p(x: float) -> str:
    return "–" if not math.isfinite(x) else f"{x:.2g}"


def cells(records: list[Record], metric: str) -> dict[str, dict[str, float]]:
    """{model: {shape: mean over seeds}} of the metric over the (model, shape) cells where every run gave a
    result (the others: cells_without_result)."""
    read = by_name()[metric].read
    runs = ok_records(records)
    failed = {(r.get("model"), shape_name(r)) for r in records if r.get("status") != "ok" or no_result(r)}
    out: dict[str, dict[str, float]] = {}
    for model in dict.fromkeys(str(r.get("model")) for r in runs):
        pairs = [(shape_name(r), read(r)) for r in runs if r.get("model") == model and (model, shape_name(r)) not in failed]
        out[model] = shape_means(pairs)
    return out


def cells_without_result(records: list[Record]) -> list[dict[str, Any]]:
    """One row per (model, shape) cell with a run that gave no result or failed: how many of its seeds, steps,
    epochs (a failed run counts as no result: it has no metrics). Only a cell with failed == seeds is not
    converged; the others converged in some seeds."""
    rows: dict[tuple[str, str], dict[str, Any]] = {}
    for r in records:
        row = rows.setdefault((str(r.get("model")), shape_name(r)), {"model": r.get("model"), "shape": shape_name(r),
                                                                      "failed": 0, "seeds": 0})
        row["seeds"] += 1
        if r.get("status") != "ok" or no_result(r):
            row["failed"] += 1
            row["steps"] = (r.get("fit") or {}).get("steps")
            row["epochs"] = (r.get("fit") or {}).get("epochs")
    return [row for row in rows.values() if row["failed"]]


def family_rows(records: list[Record]) -> list[dict[str, Any]]:
    """Each model over the shapes: chamfer and fit time (geometric), F@0.01 (mean), storage (geometric)."""
    cd, f1, fit, size = (cells(records, m) for m in (CHAMFER, FSCORE, "fit_s", "storage_bytes"))
    rows = []
    for model in cd:
        rows.append({"model": model, "chamfer": geometric(cd[model]), "fscore": share_mean(f1[model]),
                     "fit_s": geometric(fit[model]), "storage": geometric(size[model])})
    return sorted(rows, key=lambda r: r["chamfer"].center if math.isfinite(r["chamfer"].center) else math.inf)


def pair_rows(records: list[Record]) -> list[dict[str, Any]]:
    """The PAIRS present in the records: chamfer ratio over shared shapes, Holm-adjusted across the pairs."""
    cd = cells(records, CHAMFER)
    rows = [{"a": a, "b": b, "ratio": ratio(cd[a], cd[b])} for a, b in PAIRS if a in cd and b in cd]
    for row, p in zip(rows, holm([r["ratio"].p for r in rows])):
        row["p_holm"] = p
    return rows


def axis_rows(records: list[Record], tags: pd.DataFrame) -> list[dict[str, Any]]:
    """Per model and axis: Spearman rho of (tag, per-shape chamfer) over shapes, and the harder half's chamfer
    over the easier half's (geometric means; Welch t interval of the difference of mean logs); Holm across the
    axes within each model."""
    by_tag = tags.set_index("shape")
    rows = []
    for model, per_shape in cells(records, CHAMFER).items():
        model_rows = []
        for axis in AXES:
            pts = [(float(by_tag.loc[s, axis]), v) for s, v in per_shape.items()
                   if s in by_tag.index and pd.notna(by_tag.loc[s, axis]) and v > 0]
            row = {"model": model, "axis": axis, "n": len(pts), "rho": math.nan, "ratio": math.nan,
                   "lo": math.nan, "hi": math.nan, "p": math.nan}
            x = np.array([p[0] for p in pts])
            if len(pts) >= 4 and len(set(x)) > 1:
                y = np.log([p[1] for p in pts])
                row["rho"] = float(_scipy_stats.spearmanr(x, y).statistic)
                cut = np.median(x)
                hard = (x < cut) if axis in HARDER_WHEN_LOW else (x > cut)
                easy = ~hard if axis in HARDER_WHEN_LOW else (x <= cut)
                if hard.sum() >= 2 and easy.sum() >= 2:
                    row.update(welch_ratio(y[hard], y[easy]), n_hard=int(hard.sum()), n_easy=int(easy.sum()))
            model_rows.append(row)
        for row, p in zip(model_rows, holm([r["p"] for r in model_rows])):
            row["p_holm"] = p
        rows += model_rows
    return rows


def tags_markdown(tags: pd.DataFrame) -> str:
    def num(x: Any, fmt: str) -> str:
        return "open" if pd.isna(x) else format(float(x), fmt)

    rows = [[t["shape"], t["split"], t["kind"], f"{int(t['faces']):,}", num(t["thinnest"], ".3g"), str(int(t["genus"])),
             num(t["sharp_edges"], ".3g"), num(t["detail"], ".3g"), num(t["open_boundary"], ".2g"),
             str(int(t["components"])), t["provenance"], t["license"]] for _, t in tags.iterrows()]
    return pipe_table(["shape", "split", "kind", "faces", "thinnest", "genus", "creases", "detail", "open boundary",
                "components", "provenance", "license"], rows)


def per_shape_markdown(records: list[Record], tags: pd.DataFrame) -> str:
    """One row per shape: its faces and genus, the labels each sample kind got (mean over seeds), and each model's
    CD-L2 x10^3 (mean over seeds; where a run gave no result, 'no result in k of n' or, in every run, 'not
    converged')."""
    cd = cells(records, CHAMFER)
    failed = {(str(r["model"]), r["shape"]): no_result_label(r["failed"], r["seeds"])
              for r in cells_without_result(records)}
    labels = cells(records, "n_samples")
    by_tag = tags.set_index("shape")
    models = list(cd)
    label_models = [m for m in models if labels.get(m)]
    shapes = [s for s in by_tag.index if any(s in cd[m] or (m, s) in failed for m in models)]
    rows = []
    for shape in shapes:
        t = by_tag.loc[shape]
        rows.append([shape, f"{int(t['faces']):,}", str(int(t["genus"]))]
                    + [f"{labels[m][shape]:,.0f}" if shape in labels[m] else "–" for m in label_models]
                    + [failed[m, shape] if (m, shape) in failed else f"{1e3 * cd[m][shape]:.3g}"
                       if shape in cd[m] else "–" for m in models])
    header = ["shape", "faces", "genus"] + [f"labels of {m}" for m in label_models] + [f"{m} CD-L2 ×10³" for m in models]
    return pipe_table(header, rows)


def sections(records: list[Record], out_dir: str, draw: bool = True) -> list[str]:
    """The markdown sections of the suite report (and their .csv files, and by_axis.png unless not draw, written
    into out_dir)."""
    tags = tags_table(out_dir, sorted({shape_name(r) for r in records}))
    fam, pairs, axes = family_rows(records), pair_rows(records), axis_rows(records, tags)
    failed = cells_without_result(records)
    out = ["## The shapes and their measured difficulty\n\nthinnest: 1st percentile of the inward wall thickness "
           "(longest side 1; 'open': no inside); genus: handles and through-holes; creases: length of edges over 30° "
           "per sqrt(area); detail: 90th percentile of |mean curvature| in balls of radius 0.01; open boundary: share "
           "of the edge length on a boundary (ddfbench/truth/difficulty.py).\n\n" + tags_markdown(tags)]
    out.append("## Each shape\n\nMeans over seeds. labels: the training samples a learned family got on the shape "
               "(the surface strategy draws them per face, so their count follows the triangle count: a 12-triangle "
               "box gets a few dozen, a 166k-triangle scan hundreds of thousands).\n\n"
               + per_shape_markdown(records, tags))
    header = ["model", "CD-L2 ×10³, geometric mean [95 %]", "F@0.01, mean [95 %]", "fit s, geometric mean",
              "storage B, geometric mean"]
    out.append("## Each family over the evaluation shapes\n\nn: shapes (each the mean over its seeds; a shape with a "
               "run that gave no result is left out and listed below). Intervals over shapes, on the log scale for "
               "chamfer, time and bytes (never below 0); the F-score's t interval is cut to [0, 1]. "
               f"Evaluation points per surface: {_points(records)}.\n\n"
               + pipe_table(header, [[r["model"], fmt(r["chamfer"], 1e3), fmt(r["fscore"]), fmt(r["fit_s"]),
                               fmt(r["storage"])] for r in fam]))
    out.append("## Family against family, shape by shape\n\nCD-L2 of a over b: the geometric mean of the per-shape "
               "ratio over the shapes where every run of both gave a result, with the t interval of the mean log "
               "ratio; p: two-sided t test of log ratio 0; **Holm-corrected across the rows of this table** (one "
               "family of claims).\n\n"
               + pipe_table(["a", "b", "CD-L2 a / b [95 %] (n shapes)", "p", "p (Holm)"],
                     [[r["a"], r["b"], fmt(r["ratio"]), _p(r["ratio"].p), _p(r["p_holm"])] for r in pairs]))
    out.append("## Along each difficulty axis\n\nPer model: Spearman rho between the tag and the per-shape CD-L2 "
               "over the shapes that have the tag (n); the harder half (above the median tag; for thinnest, below it) "
               "over the easier half: ratio of geometric mean CD-L2 with its Welch t interval, p two-sided, "
               "**Holm-corrected across the six axes within each model**. Shapes at the median fall in the easier "
               "half. by_axis.png plots every shape.\n\n"
               + pipe_table(["model", "axis", "n", "rho", "harder / easier CD-L2 [95 %]", "p", "p (Holm)"],
                     [[r["model"], AXIS_LABELS[r["axis"]], str(r["n"]), _p(r["rho"]),
                       "–" if not math.isfinite(r["ratio"]) else
                       (f"{r['ratio']:.3g} [{r['lo']:.3g}, {r['hi']:.3g}] ({r.get('n_hard')} vs {r.get('n_easy')})"
                        if math.isfinite(r["lo"]) else f"{r['ratio']:.3g}"),
                       _p(r["p"]), _p(r["p_holm"])] for r in axes]))
    if failed:
        out.append("## Shapes with a run that gave no result (left out of the summaries above)\n\n"
                   "Not converged where every run of the cell gave no result; the others converged in some seeds "
                   "only, so their mean over seeds would mix surfaces with penalties or off-shape values.\n\n"
                   + pipe_table(["model", "shape", "runs with no result", "steps", "epochs"],
                         [[str(r["model"]), r["shape"], f"{r['failed']} of {r['seeds']}", str(r.get("steps")),
                           "–" if r.get("epochs") is None else f"{float(r['epochs']):.3g}"] for r in failed]))
    pd.DataFrame(axes).to_csv(os.path.join(out_dir, "by_axis.csv"), index=False, float_format="%.6g")
    if draw:
        plot_axes(records, tags, os.path.join(out_dir, "by_axis.png"))
    out.append("![by_axis.png](by_axis.png)")
    return out


def _points(records: list[Record]) -> str:
    found = sorted({int((r.get("config") or {}).get("eval", {}).get("n_points") or 0) for r in ok_records(records)})
    return ", ".join(f"{n:,}" for n in found) or "unknown"


def plot_axes(records: list[Record], tags: pd.DataFrame, path: str,
              scale_of: Callable[[str], str] = lambda a: "symlog" if a in ("genus", "components") else "linear") -> None:
    """One panel per axis: per-shape mean CD-L2 (log y) against the tag, one marker series per model."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by_tag = tags.set_index("shape")
    fig, axs = plt.subplots(2, 3, figsize=(13, 7.5), constrained_layout=True)
    for ax, axis in zip(axs.ravel(), AXES):
        for model, per_shape in cells(records, CHAMFER).items():
            pts = sorted((float(by_tag.loc[s, axis]), 1e3 * v) for s, v in per_shape.items()
                         if s in by_tag.index and pd.notna(by_tag.loc[s, axis]) and v > 0)
            if pts:
                ax.plot(*zip(*pts), "o", ms=5, alpha=0.8, label=model)
        ax.set_yscale("log")
        if scale_of(axis) == "symlog":
            ax.set_xscale("symlog", linthresh=1.0)
            ax.set_xlim(left=-0.3)
        else:
            ax.set_xscale(scale_of(axis))
        ax.set_xlabel(AXIS_LABELS[axis])
        ax.set_ylabel("CD-L2 ×10³ (mean over seeds)")
        ax.grid(alpha=0.3)
    axs.ravel()[0].legend(fontsize=7)
    fig.suptitle("Accuracy along each difficulty axis, one point per evaluation shape")
    fig.savefig(path, dpi=110)
    plt.close(fig)
