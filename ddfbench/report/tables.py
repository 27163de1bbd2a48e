"""Run records → one row per configuration (mean ± std over seeds, n shown) → md / csv / tex.

Values stay numeric until rendered. A row is one configuration: records whose configs differ only in
`seed` are pooled. Rows are labelled by the command-line / sweep overrides that differ between
records (the sweep's axes, e.g. `capacity=c2`), not by every config key that differs.
Failed runs are counted per row and a row with fewer ok runs than the fullest row is flagged
(`n` shows "ok/expected" and a dagger), so nothing is silently averaged over fewer seeds.
The best value per column (per shape where there are several) is marked; the metric's noise floor
(GT against an independent resample of GT) is its own row per shape.
"""

from __future__ import annotations

import json
import math
from typing import Any, Iterable

import numpy as np
import pandas as pd

from ddfbench.runs import NON_SEMANTIC_KEYS

# column -> (header, display scale, better: "low" | "high" | "" (a setting, no best))
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
    "n_samples": ("samples", 1.0, ""),
    "sampling_s": ("sample s", 1.0, "low"),
    "fit_s": ("fit s", 1.0, "low"),
    "extract_s": ("extract s", 1.0, "low"),
    "render_cold_s": ("render cold s", 1.0, "low"),
    "render_warm_s": ("render warm s", 1.0, "low"),
}
FLOOR_METRICS = ("chamfer_l2", "chamfer_l1", "fscore@0.005", "fscore@0.01", "fscore@0.02")
FLOOR_MODEL = "noise floor"  # the `model` cell of a noise-floor row
SEED_KEYS = ("seed",)
INCOMPLETE = "†"  # marks a row with fewer ok runs than the fullest row


def _flatten(prefix: str, value: Any, out: dict[str, Any]) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            _flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    else:
        out[prefix] = json.dumps(value) if isinstance(value, list) else value


def _num(value: Any) -> float:
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def override_labels(overrides: Iterable[str]) -> dict[str, str]:
    """{key: value} of a record's overrides, minus seeds and non-semantic keys (paths, threads, ...)."""
    out = {}
    for o in overrides or []:
        if "=" not in o:
            continue
        key, value = o.split("=", 1)
        bare = key.lstrip("+~")
        if bare in SEED_KEYS or bare.split(".")[0] in NON_SEMANTIC_KEYS or bare.startswith("hydra"):
            continue
        out[bare] = value
    return out


def _metric_value(name: str, m: dict[str, Any], c: dict[str, Any], sampling: dict[str, Any]) -> float:
    if name.startswith("fscore@"):
        return _num((m.get("fscore") or {}).get(name.split("@")[1]))
    if name.startswith("sided_"):
        return _num((m.get(name[: -len("_mean")]) or {}).get("mean"))
    if name == "n_samples":
        return _num(sampling.get("n_samples"))
    return _num(c[name]) if name in c else _num(m.get(name))


def record_row(rec: dict[str, Any]) -> dict[str, Any]:
    """One flat row of a record: identity, status, metrics, costs and noise floor (NaN where absent)."""
    m, c, s = rec.get("metrics") or {}, rec.get("cost") or {}, rec.get("sampling") or {}
    row: dict[str, Any] = {
        "key": rec.get("key"), "status": rec.get("status"), "error": rec.get("error"),
        "experiment": rec.get("experiment"), "model": rec.get("model"), "family": rec.get("family"),
        "shape": (rec.get("shape") or {}).get("name"), "seed": (rec.get("config") or {}).get("seed"),
        "empty": bool(m.get("empty_reconstruction")), "started": str(rec.get("started") or ""),
    }
    for name in METRICS:
        row[name] = _metric_value(name, m, c, s)
    floor = m.get("noise_floor") or {}
    for name in FLOOR_METRICS:
        row[f"noise_floor_{name}"] = _metric_value(name, floor, {}, {})
    cfg: dict[str, Any] = {}
    _flatten("", {k: v for k, v in (rec.get("config") or {}).items() if k not in SEED_KEYS}, cfg)
    row["_config"] = cfg
    row["_labels"] = override_labels(rec.get("overrides") or [])
    return row


def varying_keys(rows: list[dict[str, Any]]) -> list[str]:
    """Config keys (dotted) whose value differs between rows: together they tell configurations apart."""
    keys = sorted({k for r in rows for k in r["_config"]})
    return [k for k in keys if len({json.dumps(r["_config"].get(k), default=str) for r in rows}) > 1]


def label_keys(rows: list[dict[str, Any]]) -> list[str]:
    """Override keys whose value differs between rows (model and shape have their own columns)."""
    keys: list[str] = []
    for r in rows:
        keys += [k for k in r["_labels"] if k not in keys and k not in ("model", "shape")]
    return [k for k in keys if len({r["_labels"].get(k) for r in rows}) > 1]


def summarize(records: Iterable[dict[str, Any]]) -> pd.DataFrame:
    """One row per configuration (seeds pooled).

    Columns: model, shape, one per varying override key (its value, None where a record lacks it),
    n (ok runs), n_failed, n_expected (runs of the fullest row), n_empty (ok runs whose reconstruction
    was empty: their metrics are the defined penalty), errors, keys (record hashes),
    <metric>_mean, <metric>_std, noise_floor_<metric>_mean.
    """
    rows = [record_row(r) for r in records]
    if not rows:
        return pd.DataFrame()
    config_keys, labels = varying_keys(rows), label_keys(rows)
    groups: dict[tuple, list[dict[str, Any]]] = {}
    for r in rows:
        ident = (r["model"], r["shape"]) + tuple(json.dumps(r["_config"].get(k), default=str) for k in config_keys)
        groups.setdefault(ident, []).append(r)
    n_expected = max(len(members) for members in groups.values())
    # sweep order: models, then shapes, by when each was first run (start times have 1 s resolution)
    first: dict[tuple[str, str], str] = {}
    for r in rows:
        for axis in ("model", "shape"):
            k = (axis, str(r[axis]))
            first[k] = min(first.get(k, r["started"]), r["started"])

    def order(ms: list[dict[str, Any]]) -> tuple:
        m, s = str(ms[0]["model"]), str(ms[0]["shape"])
        return first[("model", m)], m, first[("shape", s)], s, min(x["started"] for x in ms)

    out = []
    for members in sorted(groups.values(), key=order):
        ok = [m for m in members if m["status"] == "ok"]
        entry: dict[str, Any] = {"model": members[0]["model"], "shape": members[0]["shape"]}
        for k in labels:
            entry[k] = members[0]["_labels"].get(k)
        entry["n"] = len(ok)
        entry["n_failed"] = len(members) - len(ok)
        entry["n_expected"] = n_expected
        entry["n_empty"] = sum(m["empty"] for m in ok)
        entry["errors"] = "; ".join(sorted({m["error"] for m in members if m["error"]}))
        entry["keys"] = " ".join(sorted(m["key"] for m in members))
        for name in METRICS:
            vals = np.array([m[name] for m in ok], dtype=float)
            vals = vals[np.isfinite(vals)]
            entry[f"{name}_mean"] = float(vals.mean()) if len(vals) else math.nan
            entry[f"{name}_std"] = float(vals.std(ddof=1)) if len(vals) > 1 else math.nan
        for name in FLOOR_METRICS:
            vals = np.array([m[f"noise_floor_{name}"] for m in members], dtype=float)
            vals = vals[np.isfinite(vals)]
            entry[f"noise_floor_{name}_mean"] = float(vals.mean()) if len(vals) else math.nan
        out.append(entry)
    _disambiguate(out, labels)
    return pd.DataFrame(out)


def _disambiguate(entries: list[dict[str, Any]], labels: list[str]) -> None:
    """Rows whose visible labels coincide (configs that differ elsewhere) get their first key appended."""
    visible = [(e["model"], e["shape"], *(e[k] for k in labels)) for e in entries]
    for e, v in zip(entries, visible):
        if visible.count(v) > 1:
            e["model"] = f"{e['model']} [{e['keys'].split()[0]}]"


def noise_floor_rows(df: pd.DataFrame) -> pd.DataFrame:
    """Per shape, one row: the metrics of GT against an independent resample of GT (the metric's floor)."""
    cols = [f"noise_floor_{m}_mean" for m in FLOOR_METRICS]
    if df.empty or not set(cols) <= set(df.columns):
        return pd.DataFrame()
    out = []
    for shape, part in df.groupby("shape", sort=False):
        entry: dict[str, Any] = {"model": FLOOR_MODEL, "shape": shape}
        for m in FLOOR_METRICS:
            vals = part[f"noise_floor_{m}_mean"].to_numpy(dtype=float)
            vals = vals[np.isfinite(vals)]
            entry[f"{m}_mean"] = float(vals.mean()) if len(vals) else math.nan
            entry[f"{m}_std"] = math.nan
        if any(math.isfinite(entry[f"{m}_mean"]) for m in FLOOR_METRICS):
            out.append(entry)
    return pd.DataFrame(out)


def _shown_metrics(df: pd.DataFrame) -> list[str]:
    return [m for m in METRICS if f"{m}_mean" in df and df[f"{m}_mean"].notna().any()]


def _label_columns(df: pd.DataFrame) -> list[str]:
    hidden = {"n", "n_failed", "n_expected", "n_empty", "errors", "keys"}
    return [c for c in df.columns if not c.endswith(("_mean", "_std")) and c not in hidden]


def best_mask(df: pd.DataFrame, metric: str) -> pd.Series:
    """True where a row holds the best mean of `metric` among rows of its shape (ties all marked;
    nothing marked where a shape has one value or all its values are equal)."""
    col = df[f"{metric}_mean"].astype(float)
    if not METRICS[metric][2]:
        return pd.Series(False, index=df.index)
    by_shape = col.groupby(df["shape"])
    best = by_shape.transform("min" if METRICS[metric][2] == "low" else "max")
    spread = by_shape.transform("max") - by_shape.transform("min")
    return col.notna() & (col == best) & (spread > 0)


def _fmt(mean: float, std: float, scale: float) -> str:
    if not math.isfinite(mean):
        return "–"
    m = mean * scale
    text = f"{m:.4g}" if abs(m) < 1e5 else f"{m:.3e}"
    return f"{text} ± {std * scale:.2g}" if math.isfinite(std) else text


def _n_cell(row: pd.Series) -> str:
    text = f"{row['n']}"
    if row["n"] < row["n_expected"]:
        text = f"{row['n']}/{row['n_expected']}{INCOMPLETE}"
    text += f" ({row['n_failed']} failed)" if row["n_failed"] else ""
    return text + (f" ({row['n_empty']} empty)" if row.get("n_empty") else "")


def _cells(df: pd.DataFrame, bold: tuple[str, str]) -> tuple[list[str], list[list[str]]]:
    labels, metrics = _label_columns(df), _shown_metrics(df)
    header = labels + ["n"] + [METRICS[m][0] for m in metrics]
    best = {m: best_mask(df, m) for m in metrics}
    body = []
    for i, row in df.iterrows():
        cells = ["–" if row[c] is None or (isinstance(row[c], float) and math.isnan(row[c])) else str(row[c])
                 for c in labels] + [_n_cell(row)]
        for m in metrics:
            text = _fmt(row[f"{m}_mean"], row[f"{m}_std"], METRICS[m][1])
            cells.append(f"{bold[0]}{text}{bold[1]}" if best[m][i] else text)
        body.append(cells)
    floors = noise_floor_rows(df)
    for _, row in floors.iterrows():
        cells = [FLOOR_MODEL if c == "model" else str(row["shape"]) if c == "shape" else "" for c in labels] + [""]
        cells += [_fmt(row[f"{m}_mean"], math.nan, METRICS[m][1]) if m in FLOOR_METRICS else "" for m in metrics]
        body.append(cells)
    return header, body


def _footnotes(df: pd.DataFrame) -> list[str]:
    lines = []
    if (df["n"] < df["n_expected"]).any():
        lines.append(f"{INCOMPLETE} fewer ok runs than the fullest row: its mean is over the ok runs only.")
    if "n_empty" in df and (df["n_empty"] > 0).any():
        lines.append("(k empty): k runs gave an empty reconstruction; their geometry metrics are the defined penalty.")
    for _, row in df[df["n_failed"] > 0].iterrows():
        lines.append(f"Failed ({row['model']}, {row['shape']}): {row['errors']}")
    return lines


def to_markdown(df: pd.DataFrame) -> str:
    """A GitHub markdown table, best per column (per shape) in bold, noise floor rows, failures below."""
    if df.empty:
        return "_no records_\n"
    header, body = _cells(df, ("**", "**"))
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in body]
    lines += ["", f"Bold: best per column{' per shape' if df['shape'].nunique() > 1 else ''}. "
              f"'{FLOOR_MODEL}': GT against an independent resample of GT (the metric cannot resolve below it)."]
    lines += [""] + _footnotes(df) if _footnotes(df) else []
    return "\n".join(lines) + "\n"


def _tex_escape(text: str) -> str:
    for a, b in (("\\", r"\textbackslash{}"), ("_", r"\_"), ("%", r"\%"), ("&", r"\&"), ("#", r"\#"),
                 ("{", r"\{"), ("}", r"\}"), ("±", r"$\pm$"), ("×10³", r"$\times10^3$"), ("→", r"$\to$"),
                 ("°", r"$^\circ$"), ("–", "--"), (INCOMPLETE, r"$^\dagger$")):
        text = text.replace(a, b)
    return text


def to_latex(df: pd.DataFrame) -> str:
    """A booktabs tabular, best per column (per shape) in bold, noise floor rows."""
    if df.empty:
        return "% no records\n"
    header, body = _cells(df, ("\x00", "\x01"))  # placeholders: escaped text, then the bold macro
    tex = lambda c: _tex_escape(c).replace("\x00", r"\textbf{").replace("\x01", "}")  # noqa: E731
    lines = [r"\begin{tabular}{" + "l" * len(header) + "}", r"\toprule", " & ".join(map(tex, header)) + r" \\",
             r"\midrule"]
    lines += [" & ".join(tex(c) for c in row) + r" \\" for row in body]
    lines += [r"\bottomrule", r"\end{tabular}"]
    lines += ["% " + _tex_escape(line) for line in _footnotes(df)]
    return "\n".join(lines) + "\n"


def to_csv(df: pd.DataFrame, path: str) -> None:
    """Numeric CSV: every <metric>_mean/_std unscaled, n, n_failed, n_expected, record keys; floor rows last."""
    pd.concat([df, noise_floor_rows(df)], ignore_index=True).to_csv(path, index=False)
