"""Run records → one row per configuration (mean ± std over seeds, n, 95 % interval) → md / csv / tex.

Values stay numeric until rendered. A row is one configuration: records whose configs differ only in
`seed` are pooled. Rows are labelled by the command-line / sweep overrides that differ between
records (the sweep's axes, e.g. `capacity=c2`), not by every config key that differs.
Failed runs are counted per row and a row with fewer ok runs than the fullest row is flagged
(`n` shows "ok/expected" and a dagger), so nothing is silently averaged over fewer seeds.
The metrics are those of `ddfbench.evaluate.metric_registry`. Per column (per shape where there are several)
the best mean is bold only when its t interval over seeds overlaps no other row's; otherwise the
rows whose intervals overlap the best are marked tied (report.stats). A row with an empty or off-shape run takes
no part in that ranking. The metric's noise floor (GT
against an independent resample of GT) is its own row per shape. The fit budget ("steps",
"epochs" or "wall-clock"; "built" for a family that trains nothing) is a column, beside steps, epochs and fit seconds.
"""

from __future__ import annotations

import json
import math
from typing import Any, Iterable

import numpy as np
import pandas as pd

from ddfbench.evaluate import metric_registry
from ddfbench.report.records import NOT_CONVERGED, OFF_SHAPE_RULE, empty_mesh, family_class, off_shape
from ddfbench.report.stats import INTERVAL_NAME, best_and_ties, summarize_values, within_range
from ddfbench.run.runs import NON_SEMANTIC_KEYS

FLOOR_MODEL = "noise floor"  # the `model` cell of a noise-floor row
SEED_KEYS = ("seed",)
INCOMPLETE = "†"  # marks a row with fewer ok runs than the fullest row
TIE = "≈"  # marks values whose interval overlaps the best one's


def _metrics() -> dict[str, metric_registry.Metric]:
    return metric_registry.by_name()


def _floor_metrics() -> list[str]:
    return [m.name for m in metric_registry.METRICS if m.floor]


def _flatten(prefix: str, value: Any, out: dict[str, Any]) -> None:
    if isinstance(value, dict):
        for k, v in value.items():
            _flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    else:
        out[prefix] = json.dumps(value) if isinstance(value, list) else value


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


def budget_label(rec: dict[str, Any]) -> str:
    """How the fit was bounded: "steps" | "epochs" | "wall-clock" (record fit.budget; "–" if none), or "built" for a
    family that trains nothing (its record holds the configured kind, which bound nothing)."""
    family = family_class(str(rec.get("family")))
    return "built" if family is not None and not family.learned else str((rec.get("fit") or {}).get("budget") or "–")


def record_row(rec: dict[str, Any]) -> dict[str, Any]:
    """One flat row of a record: identity, status, every registry metric and noise floor (NaN where absent)."""
    row: dict[str, Any] = {
        "key": rec.get("key"), "status": rec.get("status"), "error": rec.get("error"),
        "experiment": rec.get("experiment"), "model": rec.get("model"), "family": rec.get("family"),
        "shape": (rec.get("shape") or {}).get("name"), "seed": (rec.get("config") or {}).get("seed"),
        "empty": empty_mesh(rec), "off": off_shape(rec), "started": str(rec.get("started") or ""),
        "budget": budget_label(rec),
        # the points a surface its sampled metrics were measured on (a re-measurement's own), else its config's
        "_points": (rec.get("metrics") or {}).get("n_points") or ((rec.get("config") or {}).get("eval") or {}).get(
            "n_points"),
    }
    for metric in metric_registry.METRICS:
        row[metric.name] = metric.read(rec)
        if metric.floor:
            row[f"noise_floor_{metric.name}"] = metric.read_floor(rec)
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


def per_run(records: Iterable[dict[str, Any]]) -> pd.DataFrame:
    """One row per record: record_row's columns, with each varying override key (e.g. `capacity`) after
    `shape`, so a run can be told apart from the other runs of its configuration."""
    return per_run_of_rows([record_row(r) for r in records])


def per_run_of_rows(rows: list[dict[str, Any]]) -> pd.DataFrame:
    """per_run of records already made rows by record_row."""
    labels = label_keys(rows) if rows else []
    out = []
    for r in rows:
        row = {k: v for k, v in r.items() if not k.startswith("_")}
        at = list(row).index("shape") + 1
        items = list(row.items())
        out.append(dict(items[:at] + [(k, r["_labels"].get(k)) for k in labels] + items[at:]))
    return pd.DataFrame(out)


def summarize(records: Iterable[dict[str, Any]]) -> pd.DataFrame:
    """One row per configuration (seeds pooled).

    Columns: model, shape, one per varying override key (its value, None where a record lacks it),
    budget (steps | epochs | wall-clock | built), eval_points (points a surface the sampled metrics were measured on), n (ok
    runs), n_failed, n_expected (runs of the fullest row), n_empty (ok runs whose reconstruction
    was empty: their metrics are the defined penalty), n_off (ok runs off the shape, `off_shape`), not_converged
    (every ok run empty or off the shape: not a method result, not ranked), errors, keys (record hashes),
    <metric>_mean, <metric>_std, <metric>_ci_lo, <metric>_ci_hi (t interval over seeds),
    noise_floor_<metric>_mean.
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
        entry["budget"] = members[0]["budget"]
        entry["eval_points"] = max((m["_points"] for m in members if m["_points"]), default=None)
        entry["n"] = len(ok)
        entry["n_failed"] = len(members) - len(ok)
        entry["n_expected"] = n_expected
        entry["n_empty"] = sum(m["empty"] for m in ok)
        entry["n_off"] = sum(m["off"] for m in ok)
        entry["not_converged"] = bool(ok) and entry["n_empty"] + entry["n_off"] == len(ok)  # nothing to rank
        entry["errors"] = "; ".join(sorted({m["error"] for m in members if m["error"]}))
        entry["keys"] = " ".join(sorted(m["key"] for m in members))
        for name in _metrics():
            summary = within_range(summarize_values(m[name] for m in ok), name)
            entry[f"{name}_mean"], entry[f"{name}_std"] = summary.mean, summary.std
            entry[f"{name}_ci_lo"], entry[f"{name}_ci_hi"] = summary.lo, summary.hi
            entry[f"{name}_n"] = summary.n  # runs that define it: fewer than n where a run has none (NaN)
        for name in _floor_metrics():
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
    floor_metrics = _floor_metrics()
    cols = [f"noise_floor_{m}_mean" for m in floor_metrics]
    if df.empty or not set(cols) <= set(df.columns):
        return pd.DataFrame()
    out = []
    for shape, part in df.groupby("shape", sort=False):
        entry: dict[str, Any] = {"model": FLOOR_MODEL, "shape": shape}
        for m in floor_metrics:
            vals = part[f"noise_floor_{m}_mean"].to_numpy(dtype=float)
            vals = vals[np.isfinite(vals)]
            entry[f"{m}_mean"] = float(vals.mean()) if len(vals) else math.nan
            entry[f"{m}_std"] = math.nan
        if any(math.isfinite(entry[f"{m}_mean"]) for m in floor_metrics):
            out.append(entry)
    return pd.DataFrame(out)


def _shown_metrics(df: pd.DataFrame) -> list[str]:
    return [name for name, m in _metrics().items()
            if m.shown and f"{name}_mean" in df and df[f"{name}_mean"].notna().any()]


def _label_columns(df: pd.DataFrame) -> list[str]:
    hidden = {"n", "n_failed", "n_expected", "n_empty", "n_off", "not_converged", "errors", "keys", "eval_points"}
    hidden |= {f"{m}_n" for m in _metrics()}
    return [c for c in df.columns if not c.endswith(("_mean", "_std", "_ci_lo", "_ci_hi")) and c not in hidden]


def _defined_in(row: pd.Series, metric: str) -> str:
    """' (of k)' when the metric is defined in fewer of the row's runs than n (k > 0), else ''."""
    k = row.get(f"{metric}_n")
    return f" (of {int(k)})" if k is not None and 0 < k < row["n"] else ""


def ranked(df: pd.DataFrame) -> pd.DataFrame:
    """The rows that take part in the ranking: those with no empty and no off-shape run (a penalty or a fit that
    never found the shape in its mean is not a method result, and its wide interval would tie it with anything)."""
    if "n_empty" not in df:
        return df
    return df[df["n_empty"] + df["n_off"] == 0]


def marks(df: pd.DataFrame, metric: str) -> pd.Series:
    """Per row "best", "tie" or "": per shape, among the ranked rows, the best mean of `metric` is "best" only when
    its interval overlaps no other row's, else it and the rows overlapping it are "tie" (report.stats)."""
    out = pd.Series("", index=df.index, dtype=object)
    better = _metrics()[metric].better
    for _, part in ranked(df).groupby("shape", sort=False):
        means = part[f"{metric}_mean"].astype(float).tolist()
        intervals = list(zip(part[f"{metric}_ci_lo"].astype(float), part[f"{metric}_ci_hi"].astype(float)))
        for i, mark in best_and_ties(means, intervals, better).items():
            out[part.index[i]] = mark
    return out


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
    text += f" ({row['n_empty']} empty)" if row.get("n_empty") else ""
    text += f" ({row['n_off']} off the shape)" if row.get("n_off") else ""
    return text + (f" {NOT_CONVERGED}" if row.get("not_converged") else "")


def _cells(df: pd.DataFrame, bold: tuple[str, str]) -> tuple[list[str], list[list[str]]]:
    labels, metrics = _label_columns(df), _shown_metrics(df)
    registry = _metrics()
    header = labels + ["n"] + [registry[m].label for m in metrics]
    mark = {m: marks(df, m) for m in metrics}
    body = []
    for i, row in df.iterrows():
        cells = ["–" if row[c] is None or (isinstance(row[c], float) and math.isnan(row[c])) else str(row[c])
                 for c in labels] + [_n_cell(row)]
        for m in metrics:
            if row.get("not_converged") and registry[m].penalty is not None:
                cells.append("–")  # a penalty or a fit that never found the shape: no method result (table.csv keeps it)
                continue
            text = _fmt(row[f"{m}_mean"], row[f"{m}_std"], registry[m].scale) + _defined_in(row, m)
            cells.append(f"{bold[0]}{text}{bold[1]}" if mark[m][i] == "best" else
                         f"{text} {TIE}" if mark[m][i] == "tie" else text)
        body.append(cells)
    floors = noise_floor_rows(df)
    for _, row in floors.iterrows():
        cells = [FLOOR_MODEL if c == "model" else str(row["shape"]) if c == "shape" else "" for c in labels] + [""]
        cells += [_fmt(row[f"{m}_mean"], math.nan, registry[m].scale) if registry[m].floor else
                  "0 (exact)" if m.startswith("p2s_") else "" for m in metrics]
        body.append(cells)
    return header, body


def _points_phrase(df: pd.DataFrame) -> str:
    """How many points a surface the sampled geometry metrics (and their noise floor) were measured on."""
    counts = sorted({int(v) for v in df.get("eval_points", pd.Series(dtype=float)).dropna()})
    if not counts:
        return "the evaluation point count is not recorded"
    return f"sampled geometry metrics on {' or '.join(f'{c:,}' for c in counts)} points a surface" + (
        " (by row: table.csv's eval_points)" if len(counts) > 1 else "")


def _partial_metrics(df: pd.DataFrame) -> bool:
    """Whether a shown metric of some row is defined in fewer of its runs than n."""
    return any(_defined_in(row, m) for _, row in df.iterrows() for m in _shown_metrics(df))


def _footnotes(df: pd.DataFrame) -> list[str]:
    lines = []
    if (df["n"] < df["n_expected"]).any():
        lines.append(f"{INCOMPLETE} fewer ok runs than the fullest row: its mean is over the ok runs only.")
    if "n_empty" in df and (df["n_empty"] > 0).any():
        lines.append("(k empty): k runs gave an empty reconstruction; their geometry metrics are the defined penalty, "
                     "and the row is not ranked.")
    if "n_off" in df and (df["n_off"] > 0).any():
        lines.append(f"(k off the shape): k runs gave a surface with {OFF_SHAPE_RULE} (no sampled point of either "
                     "surface near the other: the fit never found the shape); their measured metrics stay in the mean, and the "
                     "row is not ranked.")
    if _partial_metrics(df):
        lines.append("(of k): the value is defined in k of the row's n runs (a depth error needs pixels that both "
                     "the render and the reference hit, a level offset a non-empty mesh); its mean, std and interval are over those k.")
    if "not_converged" in df and df["not_converged"].astype(bool).any():
        lines.append(f"{NOT_CONVERGED}: every run's reconstruction was empty or off the shape, so the row is not a method "
                     "result: its geometry cells are blank (table.csv keeps the values), it is not ranked, and its steps "
                     "and epochs columns say how much it was trained.")
    for _, row in df[df["n_failed"] > 0].iterrows():
        lines.append(f"Failed ({row['model']}, {row['shape']}): {row['errors']}")
    return lines


def pipe_lines(header: list[str], rows: Iterable[list[str]]) -> list[str]:
    """The lines of pipe_table, without line ends: a table among a report's other markdown lines."""
    return ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)] + ["| " + " | ".join(r) + " |" for r in rows]


def pipe_table(header: list[str], rows: Iterable[list[str]]) -> str:
    """A GitHub markdown table of string cells (header, then one line per row)."""
    return "\n".join(pipe_lines(header, rows)) + "\n"


def to_markdown(df: pd.DataFrame) -> str:
    """A GitHub markdown table, best per column (per shape) in bold, noise floor rows, failures below."""
    if df.empty:
        return "_no records_\n"
    lines = pipe_lines(*_cells(df, ("**", "**")))
    per_shape = " per shape" if df["shape"].nunique() > 1 else ""
    lines += ["", f"Mean ± std over seeds, n runs; {_points_phrase(df)}. Bold: best per column{per_shape}, its {INTERVAL_NAME} "
              f"(table.csv: _ci_lo, _ci_hi; cut to the metric's range) overlapping no other row's; {TIE}: tied, the intervals of these "
              f"values overlap the best one's (with n = 1 every value is tied). "
              f"'{FLOOR_MODEL}': GT against an independent resample of GT (the sampled metric cannot resolve "
              f"below it); the point-to-surface (p2s) chamfer measures exact distances and has no such floor."]
    lines += [""] + _footnotes(df) if _footnotes(df) else []
    return "\n".join(lines) + "\n"


CONSOLE_METRICS = ("chamfer_l2", "fscore@0.01", "fit_s", "render_warm_s", "storage_bytes")  # the terminal's few


def console_table(df: pd.DataFrame) -> str:
    """The few columns a terminal shows (model, shape, the sweep's varying settings, n, CONSOLE_METRICS: mean, and
    ± std where it is not 0) in lines of about 100 characters without settings; the full table is the report's
    (to_markdown)."""
    if df.empty:
        return "(no records)\n"
    registry = _metrics()
    short = {"render_warm_s": "frame s", "storage_bytes": "bytes"}
    settings = [c for c in _label_columns(df) if c not in ("model", "shape", "budget")]
    header = ["model", "shape", *settings, "n"] + [short.get(m, registry[m].label) for m in CONSOLE_METRICS]
    rows = []
    for _, row in df.iterrows():
        if row["model"] == FLOOR_MODEL:
            continue
        cells = [str(row["model"]), str(row["shape"]), *("–" if row[c] is None else str(row[c]) for c in settings),
                 _n_cell(row)]
        for name in CONSOLE_METRICS:
            mean, std, scale = row[f"{name}_mean"], row[f"{name}_std"], registry[name].scale
            spread = row["n"] > 1 and math.isfinite(std) and std > 0
            cells.append(f"{mean * scale:.3g}" + (f"±{std * scale:.1g}" if spread else "") if math.isfinite(mean) else "–")
        rows.append(cells)
    widths = [max(len(str(c)) for c in column) for column in zip(header, *rows)]
    return "\n".join("  ".join(str(c).ljust(w) for c, w in zip(line, widths)).rstrip() for line in [header, *rows]) + "\n"


def _tex_escape(text: str) -> str:
    for a, b in (("\\", r"\textbackslash{}"), ("_", r"\_"), ("%", r"\%"), ("&", r"\&"), ("#", r"\#"),
                 ("{", r"\{"), ("}", r"\}"), ("±", r"$\pm$"), ("×10³", r"$\times10^3$"), ("→", r"$\to$"), (TIE, r"$\approx$"),
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
    """Numeric CSV: every <metric>_mean/_std/_ci_lo/_ci_hi unscaled (t interval over seeds, 95 %), n,
    n_failed, n_expected, record keys; floor rows last."""
    pd.concat([df, noise_floor_rows(df)], ignore_index=True).to_csv(path, index=False)
