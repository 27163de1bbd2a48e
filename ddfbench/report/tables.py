"""Run records → one row per configuration (mean ± std over seeds, n shown) → md / csv / tex.

Values stay numeric until rendered; failed runs are counted per row, never silently averaged away.
"""

from __future__ import annotations

import json
import math
from typing import Any, Iterable

import numpy as np
import pandas as pd

# column -> (header, display scale, better: "low" | "high")
METRICS: dict[str, tuple[str, float, str]] = {
    "chamfer_l2": ("CD-L2 ×10³", 1e3, "low"),
    "chamfer_l1": ("CD-L1 ×10³", 1e3, "low"),
    "fscore@0.005": ("F@0.005", 1.0, "high"),
    "fscore@0.01": ("F@0.01", 1.0, "high"),
    "fscore@0.02": ("F@0.02", 1.0, "high"),
    "sided_gt_to_rec_mean": ("GT→rec ×10³", 1e3, "low"),
    "sided_rec_to_gt_mean": ("rec→GT ×10³", 1e3, "low"),
    "normal_consistency": ("NC", 1.0, "high"),
    "mask_iou": ("mask IoU", 1.0, "high"),
    "depth_mae": ("depth MAE ×10³", 1e3, "low"),
    "normal_angle_deg": ("normal err °", 1.0, "low"),
    "storage_bytes": ("storage B", 1.0, "low"),
    "n_params": ("params", 1.0, "low"),
    "sampling_s": ("sample s", 1.0, "low"),
    "fit_s": ("fit s", 1.0, "low"),
    "extract_s": ("extract s", 1.0, "low"),
    "render_cold_s": ("render cold s", 1.0, "low"),
    "render_warm_s": ("render warm s", 1.0, "low"),
}
SEED_KEYS = ("seed",)


def _flatten(prefix: str, value: Any, out: dict[str, Any]) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            _flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    else:
        out[prefix] = json.dumps(value) if isinstance(value, list) else value


def _num(value: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return math.nan
    return v


def record_row(rec: dict[str, Any]) -> dict[str, Any]:
    """One flat row of a record: identity, status, metrics and costs (NaN where absent)."""
    m, c = rec.get("metrics") or {}, rec.get("cost") or {}
    row: dict[str, Any] = {
        "key": rec.get("key"), "status": rec.get("status"), "error": rec.get("error"),
        "experiment": rec.get("experiment"), "model": rec.get("model"), "family": rec.get("family"),
        "shape": (rec.get("shape") or {}).get("name"), "seed": (rec.get("config") or {}).get("seed"),
    }
    for name in METRICS:
        if name.startswith("fscore@"):
            row[name] = _num((m.get("fscore") or {}).get(name.split("@")[1]))
        elif name.startswith("sided_"):
            row[name] = _num((m.get(name[: -len("_mean")]) or {}).get("mean"))
        elif name in c:
            row[name] = _num(c[name])
        else:
            row[name] = _num(m.get(name))
    row["noise_floor_chamfer_l2"] = _num((m.get("noise_floor") or {}).get("chamfer_l2"))
    cfg: dict[str, Any] = {}
    _flatten("", {k: v for k, v in (rec.get("config") or {}).items() if k not in SEED_KEYS}, cfg)
    row["_config"] = cfg
    return row


def varying_keys(rows: list[dict[str, Any]]) -> list[str]:
    """Config keys (dotted) whose value differs between rows: they label the table's rows."""
    keys = sorted({k for r in rows for k in r["_config"]})
    return [k for k in keys if len({json.dumps(r["_config"].get(k), default=str) for r in rows}) > 1]


def summarize(records: Iterable[dict[str, Any]]) -> pd.DataFrame:
    """One row per configuration (seeds pooled): <metric>_mean, <metric>_std, n, n_failed, errors."""
    rows = [record_row(r) for r in records]
    if not rows:
        return pd.DataFrame()
    label_keys = [k for k in varying_keys(rows) if k not in ("model.family",)]
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        label = (r["model"], r["shape"]) + tuple(json.dumps(r["_config"].get(k), default=str) for k in label_keys)
        groups.setdefault(label, []).append(r)
    out = []
    for label, members in groups.items():
        ok = [m for m in members if m["status"] == "ok"]
        entry: dict[str, Any] = {"model": label[0], "shape": label[1]}
        for k, v in zip(label_keys, label[2:]):
            if k not in ("shape.name",):
                entry[k] = json.loads(v)
        entry["n"] = len(ok)
        entry["n_failed"] = len(members) - len(ok)
        entry["errors"] = "; ".join(sorted({m["error"] for m in members if m["error"]}))
        entry["keys"] = " ".join(sorted(m["key"] for m in members))
        for name in list(METRICS) + ["noise_floor_chamfer_l2"]:
            vals = np.array([m[name] for m in ok], dtype=float)
            vals = vals[np.isfinite(vals)]
            entry[f"{name}_mean"] = float(vals.mean()) if len(vals) else math.nan
            entry[f"{name}_std"] = float(vals.std(ddof=1)) if len(vals) > 1 else math.nan
        out.append(entry)
    return pd.DataFrame(out)


def _shown_metrics(df: pd.DataFrame) -> list[str]:
    return [m for m in METRICS if f"{m}_mean" in df and df[f"{m}_mean"].notna().any()]


def _label_columns(df: pd.DataFrame) -> list[str]:
    stats = {c for c in df.columns if c.endswith("_mean") or c.endswith("_std")}
    return [c for c in df.columns if c not in stats and c not in ("n", "n_failed", "errors", "keys")]


def _best(df: pd.DataFrame, metric: str) -> float:
    vals = df[f"{metric}_mean"]
    return vals.min() if METRICS[metric][2] == "low" else vals.max()


def _fmt(mean: float, std: float, scale: float) -> str:
    if not math.isfinite(mean):
        return "–"
    m = mean * scale
    text = f"{m:.4g}" if abs(m) < 1e5 else f"{m:.3e}"
    return f"{text} ± {std * scale:.2g}" if math.isfinite(std) else text


def _cells(df: pd.DataFrame, bold: tuple[str, str]) -> tuple[list[str], list[list[str]]]:
    labels, metrics = _label_columns(df), _shown_metrics(df)
    header = labels + ["n"] + [METRICS[m][0] for m in metrics]
    body = []
    for _, row in df.iterrows():
        n = f"{row['n']}" + (f" ({row['n_failed']} failed)" if row["n_failed"] else "")
        cells = [str(row[c]) for c in labels] + [n]
        for m in metrics:
            text = _fmt(row[f"{m}_mean"], row[f"{m}_std"], METRICS[m][1])
            if math.isfinite(row[f"{m}_mean"]) and row[f"{m}_mean"] == _best(df, m) and len(df) > 1:
                text = f"{bold[0]}{text}{bold[1]}"
            cells.append(text)
        body.append(cells)
    return header, body


def noise_floor_rows(df: pd.DataFrame) -> dict[str, float]:
    """Per shape: the chamfer L2 of GT against an independent resample of GT (the metric's floor)."""
    if "noise_floor_chamfer_l2_mean" not in df:
        return {}
    floors = df.groupby("shape")["noise_floor_chamfer_l2_mean"].mean()
    return {s: float(v) for s, v in floors.items() if math.isfinite(v)}


def to_markdown(df: pd.DataFrame) -> str:
    """A GitHub markdown table, best per column in bold, failures named below it."""
    if df.empty:
        return "_no records_\n"
    header, body = _cells(df, ("**", "**"))
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in body]
    for shape, floor in noise_floor_rows(df).items():
        lines.append(f"\nMetric noise floor ({shape}: GT vs an independent GT resample): CD-L2 ×10³ = {floor * 1e3:.4g}")
    failed = df[df["n_failed"] > 0]
    for _, row in failed.iterrows():
        lines.append(f"\nFailed ({row['model']}, {row['shape']}): {row['errors']}")
    return "\n".join(lines) + "\n"


def _tex_escape(text: str) -> str:
    for a, b in (("\\", r"\textbackslash{}"), ("_", r"\_"), ("%", r"\%"), ("&", r"\&"), ("#", r"\#"),
                 ("±", r"$\pm$"), ("×10³", r"$\times10^3$"), ("→", r"$\to$"), ("°", r"$^\circ$"), ("–", "--")):
        text = text.replace(a, b)
    return text


def to_latex(df: pd.DataFrame) -> str:
    """A booktabs tabular, best per column in bold."""
    if df.empty:
        return "% no records\n"
    header, body = _cells(df, ("\\textbf{", "}"))
    esc = lambda c: c if c.startswith("\\textbf{") and _tex_escape(c) == c else _tex_escape(c)  # noqa: E731
    lines = [r"\begin{tabular}{" + "l" * len(header) + "}", r"\toprule", " & ".join(map(_tex_escape, header)) + r" \\",
             r"\midrule"]
    lines += [" & ".join(esc(c) for c in row) + r" \\" for row in body]
    lines += [r"\bottomrule", r"\end{tabular}"]
    return "\n".join(lines) + "\n"


def to_csv(df: pd.DataFrame, path: str) -> None:
    """Numeric CSV: every <metric>_mean/_std column unscaled, n and n_failed."""
    df.to_csv(path, index=False)
