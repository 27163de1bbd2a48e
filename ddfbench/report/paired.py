"""Paired comparisons: settings run on the same shapes and seeds, compared pair by pair.

A pair is two ok records with the same pair key (shape, seed and whatever else must match, e.g. the
label count); the difference a − b per pair is summarized with its t interval (report.stats). The
ratio a / b is summarized on the log scale (geometric mean ratio and its interval), which suits
metrics that span decades (chamfer across sample counts).
"""

from __future__ import annotations

import math
from typing import Any, Callable, Iterable

import numpy as np

from ddfbench.evaluate.metric_registry import Metric, by_name
from ddfbench.report.records import SURFACE_FACTORS, Record, ok_records
from ddfbench.report.stats import Summary, holm, sig3, summarize_values, t_test_p
from ddfbench.report.tables import pipe_lines


def values(records: Iterable[Record], metric: str | Metric, select: Callable[[Record], bool],
           pair_key: Callable[[Record], tuple]) -> dict[tuple, float]:
    """{pair key: metric value} of the ok records `select` keeps (finite values only); metric: a registry name, or a
    Metric read by one report alone."""
    read = (metric if isinstance(metric, Metric) else by_name()[metric]).read
    out = {pair_key(r): read(r) for r in ok_records(records) if select(r)}
    return {k: v for k, v in out.items() if math.isfinite(v)}


def difference(a: dict[tuple, float], b: dict[tuple, float]) -> Summary:
    """a − b over the shared pair keys."""
    return summarize_values([a[k] - b[k] for k in a if k in b])


def log_ratio(a: dict[tuple, float], b: dict[tuple, float]) -> Summary:
    """ln(a / b) over the shared pair keys with both values > 0 (exp of its bounds: the ratio's interval)."""
    return summarize_values([math.log(a[k] / b[k]) for k in a if k in b and a[k] > 0 and b[k] > 0])


def seed_key(rec: Record) -> tuple:
    """(shape, seed): the pairing of settings run on the same shapes and seeds."""
    return (rec.get("shape") or {}).get("name"), (rec.get("config") or {}).get("seed")


def compare_settings(records: list[Record], metric: str, setting: Callable[[Record], str], baseline: str,
                     pair_key: Callable[[Record], tuple] = seed_key) -> list[dict[str, Any]]:
    """Each setting other than `baseline` against it: rows {setting, n, diff (Summary), ratio (Summary)}."""
    names = list(dict.fromkeys(setting(r) for r in ok_records(records)))
    base = values(records, metric, lambda r: setting(r) == baseline, pair_key)
    rows = []
    for name in names:
        if name == baseline:
            continue
        vals = values(records, metric, lambda r, n=name: setting(r) == n, pair_key)
        rows.append({"setting": name, "diff": difference(vals, base), "ratio": log_ratio(vals, base)})
    return rows


def to_markdown(rows: list[dict[str, Any]], metric: str, baseline: str, what: str) -> str:
    """A table of paired differences and ratios against the baseline, with t intervals; a setting is separated from
    the baseline when the Holm-adjusted p of its log ratio (the table's rows one family) is below 0.05."""
    m = by_name()[metric]
    ps = [t_test_p(row["ratio"]) for row in rows]
    lines = [f"Paired against **{baseline}** ({what}): {m.label} difference (setting − baseline) and ratio "
             f"(geometric mean of setting / baseline), each with its 95 % t interval over the pairs. Separated: the "
             f"ratio's two-sided p (t test of the mean log ratio against 0), Holm-adjusted across the table's "
             f"{sum(math.isfinite(p) for p in ps)} settings, is below 0.05.", ""]
    cells = []
    for row, p, p_holm in zip(rows, ps, holm(ps)):
        d, r = row["diff"], row["ratio"]
        cells.append([f"{row['setting']}", f"{d.n}", sig3(d.mean, m.scale),
                      f"[{sig3(d.lo, m.scale)}, {sig3(d.hi, m.scale)}]", sig3(np.exp(r.mean), 1),
                      f"[{sig3(np.exp(r.lo), 1)}, {sig3(np.exp(r.hi), 1)}]",
                      f"{sig3(p, 1)}, {sig3(p_holm, 1)}", "yes" if p_holm < 0.05 else "no"])
    lines += pipe_lines(["setting", "pairs", "difference", "95 % interval", "ratio", "95 % interval", "p, Holm",
                         "separated from 1"], cells)
    return "\n".join(lines) + "\n"


def surface_levels(rec: Record) -> str:
    """The ablation's setting: "s_fc=.. s_dr=.. s_p=.." of a record's sampling."""
    s = rec.get("sampling") or {}
    return " ".join(f"{k}={s.get(k)}" for k in SURFACE_FACTORS)


def strategy(rec: Record) -> str:
    return str((rec.get("sampling") or {}).get("strategy"))


def strategy_pair_key(rec: Record) -> tuple:
    """(shape, seed, labels trained on): strategies compared at matched label counts."""
    return (*seed_key(rec), (rec.get("sampling") or {}).get("n_samples"))


# experiment -> (setting of a record, baseline setting, pair key, what the pairs share)
PAIRED_DESIGNS: dict[str, tuple[Callable[[Record], str], str, Callable[[Record], tuple], str]] = {
    "ablation": (surface_levels, "s_fc=10 s_dr=10 s_p=10", seed_key, "same shape and seed"),
    "sampling": (strategy, "random", strategy_pair_key, "same shape, seed and number of labels"),
}


def paired_report(experiment: str, records: list[Record], metrics: tuple[str, ...] = ("chamfer_l2", "p2s_chamfer_l2")) -> str | None:
    """paired.md for an experiment with a paired design (PAIRED_DESIGNS), None otherwise."""
    if experiment not in PAIRED_DESIGNS:
        return None
    setting, baseline, key, what = PAIRED_DESIGNS[experiment]
    parts = [f"# {experiment}: paired comparisons", ""]
    for metric in metrics:
        parts += [to_markdown(compare_settings(records, metric, setting, baseline, key), metric, baseline, what)]
    return "\n".join(parts)
