"""Render speed at matched accuracy: each family's fastest setting that is at least as accurate as the DDF.

`python -m ddfbench.report.matched RENDER_TIME RENDER_MATCHED [--out DIR]` (folders of run records or the reports'
compact records, e.g. reports/render_time/records.jsonl.gz reports/render_matched/records.jsonl.gz): the table on
stdout, and with --out also DIR/matched.md and DIR/matched.csv.

A family's settings are its rows: sphere-tracer settings (model.trace: eps, eps_abs, omega) for the SDF
families, the mesh LODs for the mesh family. Per shape and image size, against every reference (the
`ddf_tuned` model) row, a family's matched setting is its fastest (lowest mean warm render time) whose mean
depth error is at most the reference's and whose mean mask IoU is at least the reference's (depth error is taken on
pixels both renders hit, so a tracer that loses the silhouette would look accurate by it alone); the default
setting (no tracer override, full mesh) stands beside it. Speed-up = the setting's warm render time / the
reference's (> 1: the DDF renders faster).
Means over seeds with n; depth error in normalized units (×10³ in the table), warm time in seconds.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from typing import Any, Iterable

import pandas as pd

from ddfbench.core.atomic import write_atomic
from ddfbench.core.errors import InputError
from ddfbench.report import compact
from ddfbench.report.stats import sig3, summarize_values
from ddfbench.report.tables import override_labels, pipe_lines

REFERENCE = "ddf_tuned"  # the DDF that render_time runs (its tuned preset); tests check it is a member
ERROR, MASK, SPEED = ("metrics", "depth_mae"), ("metrics", "mask_iou"), ("cost", "render_warm_s")
NOT_REACHED = "not reached"


def _measure(rec: dict[str, Any], path: tuple[str, str]) -> float:
    v = (rec.get(path[0]) or {}).get(path[1])
    return float(v) if isinstance(v, (int, float)) else math.nan


TRACE = "model.trace."  # the overrides a tracer sweep sets (render_matched: ++model.trace.eps_abs=..., omega)


def _parsed(text: str) -> Any:
    try:
        return float(text)
    except ValueError:
        return text


def setting_label(rec: dict[str, Any]) -> str:
    """What distinguishes a row inside its family: the model name and the tracer keys its sweep set (its
    `model.trace.*` overrides; the trace block a preset carries in its config is that preset's default)."""
    trace = {key[len(TRACE):]: _parsed(value) for key, value in override_labels(rec.get("overrides") or []).items()
             if key.startswith(TRACE)}
    return f"{rec.get('model')} {json.dumps(trace, sort_keys=True)}" if trace else str(rec.get("model"))


def settings_table(records: Iterable[dict[str, Any]]) -> pd.DataFrame:
    """One row per (family, setting, shape, image size), seeds pooled: error/speed mean, std, n, interval."""
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for rec in records:
        if rec.get("status") != "ok":
            continue
        scene = rec.get("scene") or {}
        key = (rec.get("family"), setting_label(rec), rec.get("model"), (rec.get("shape") or {}).get("name"),
               f"{scene.get('width')}x{scene.get('height')}")
        groups.setdefault(key, []).append(rec)
    rows = []
    for (family, setting, model, shape, size), recs in groups.items():
        row = {"family": family, "setting": setting, "model": model, "shape": shape, "size": size,
               # the untouched tracer of the preset that was run; of the mesh, the full mesh (LODs are settings)
               "default": setting == model and (family != "mesh" or model == "mesh")}
        for name, path in (("depth_mae", ERROR), ("mask_iou", MASK), ("render_warm_s", SPEED)):
            s = summarize_values(_measure(r, path) for r in recs)
            row.update({f"{name}_mean": s.mean, f"{name}_std": s.std, f"{name}_ci_lo": s.lo,
                        f"{name}_ci_hi": s.hi, f"{name}_n": s.n})
        rows.append(row)
    return pd.DataFrame(rows)


def matched_table(records: Iterable[dict[str, Any]], reference: str = REFERENCE) -> pd.DataFrame:
    """Per (shape, size, reference row, other family): the default and the matched setting with speed-ups.

    matched = the family's fastest setting with mean depth error <= the reference's and mean mask IoU >= the
    reference's (where the reference has one; "not reached" when none is that accurate: the family's setting of
    least depth error is then shown)."""
    table = settings_table(records)
    out = []
    if table.empty:
        return pd.DataFrame(out)
    for (shape, size), part in table.groupby(["shape", "size"], sort=False):
        for _, ref in part[part["model"] == reference].iterrows():
            others = part[part["family"] != ref["family"]]
            for family, fam in others.groupby("family", sort=False):
                as_whole = (fam["mask_iou_mean"] >= ref["mask_iou_mean"] if pd.notna(ref["mask_iou_mean"])
                            else True)  # a reference without a mask IoU: depth error alone
                ok = fam[(fam["depth_mae_mean"] <= ref["depth_mae_mean"]) & as_whole]
                pick = ok.nsmallest(1, "render_warm_s_mean") if len(ok) else fam.nsmallest(1, "depth_mae_mean")
                default = fam[fam["default"]].nsmallest(1, "depth_mae_mean")
                entry = {"shape": shape, "size": size, "reference": ref["setting"],
                         "reference_depth_mae": ref["depth_mae_mean"], "reference_mask_iou": ref["mask_iou_mean"],
                         "reference_warm_s": ref["render_warm_s_mean"],
                         "reference_n": ref["render_warm_s_n"], "family": family}
                for tag, row in (("default", default), ("matched", pick)):
                    r = row.iloc[0] if len(row) else None
                    entry[f"{tag}_setting"] = None if r is None else r["setting"]
                    entry[f"{tag}_depth_mae"] = math.nan if r is None else r["depth_mae_mean"]
                    entry[f"{tag}_mask_iou"] = math.nan if r is None else r["mask_iou_mean"]
                    entry[f"{tag}_warm_s"] = math.nan if r is None else r["render_warm_s_mean"]
                    entry[f"{tag}_n"] = 0 if r is None else r["render_warm_s_n"]
                    entry[f"{tag}_speedup"] = (math.nan if r is None else r["render_warm_s_mean"] / ref["render_warm_s_mean"])
                entry["matched_reached"] = bool(len(ok))
                out.append(entry)
    return pd.DataFrame(out)


def to_markdown(df: pd.DataFrame) -> str:
    """The matched table as markdown, one line per (shape, size, reference, family)."""
    header = ["shape", "size", "DDF depth err ×10³", "DDF mask IoU", "DDF warm s", "family", "default setting",
              "depth err ×10³", "mask IoU", "warm s", "× DDF time", "matched setting", "depth err ×10³",
              "mask IoU", "warm s", "× DDF time"]
    rows = []
    for _, r in df.iterrows():
        matched = r["matched_setting"] if r["matched_reached"] else f"{NOT_REACHED} (most accurate: {r['matched_setting']})"
        rows.append([
            str(r["shape"]), str(r["size"]), sig3(r["reference_depth_mae"], 1e3), sig3(r["reference_mask_iou"]),
            sig3(r["reference_warm_s"]), str(r["family"]), str(r["default_setting"]),
            sig3(r["default_depth_mae"], 1e3), sig3(r["default_mask_iou"]), sig3(r["default_warm_s"]),
            sig3(r["default_speedup"]), matched, sig3(r["matched_depth_mae"], 1e3), sig3(r["matched_mask_iou"]),
            sig3(r["matched_warm_s"]), sig3(r["matched_speedup"])])
    lines = pipe_lines(header, rows)
    lines += ["", "Means over seeds (n in table.csv). × DDF time: the family's warm render time over the DDF's "
              "(> 1: the DDF is faster). Matched: the family's fastest setting whose mean depth error is at most "
              "the DDF's and whose mean mask IoU is at least the DDF's; 'not reached': no setting is that "
              "accurate (the setting of least depth error is shown)."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ddfbench.report.matched", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("records", nargs="+",
                        help="folders of run records or compact records (*.jsonl.gz): render_time, render_matched")
    parser.add_argument("--out", help="folder for matched.md and matched.csv (default: print only)")
    args = parser.parse_args(argv)
    missing = [d for d in args.records if not (os.path.isdir(d) or (d.endswith(".jsonl.gz") and os.path.isfile(d)))]
    if missing:
        print(f"ddfbench.report.matched: {', '.join(missing)}: no folder of run records or .jsonl.gz file",
              file=sys.stderr)
        return 2
    try:
        df = matched_table([r for source in args.records for r in compact.load_records(source, strict=True)])
        if df.empty:
            raise InputError(f"{', '.join(args.records)}: no finished {REFERENCE} run beside another family's on its "
                             "shape and frame size")
        md = to_markdown(df)
        if args.out:
            from ddfbench.run.checks import writable_folder  # (it imports the families: torch)

            writable_folder(args.out, "--out ")
            write_both(args.out, md, df)
    except InputError as exc:
        print(f"ddfbench.report.matched: {exc}: nothing written", file=sys.stderr)
        return 2
    print(md)
    return 0


def write_both(out: str, md: str, df: pd.DataFrame) -> None:
    """out/matched.md and out/matched.csv, each whole or not at all (core.atomic)."""
    for name, text in (("matched.md", md), ("matched.csv", df.to_csv(index=False))):
        write_atomic(os.path.join(out, name), lambda fh, text=text: fh.write(text))


if __name__ == "__main__":
    sys.exit(main())
