"""One model's figures over every seed run so far, pooled from the committed reports of one folder, where the
records of the first two seeds went with the machine that ran them (reports/gan_epochs_tuned: gan_sdf_tuned at
the thesis' 40 epochs, code 332b432):

  table.csv          the two-seed report (seeds 0 and 1, n = 2)
  seed0/table.csv    seed 0's one-seed report (n = 1, written while seed 1 ran, before reports wrote runs.csv);
                     seed 1 is then 2 × the two-seed mean − seed 0, column by column
  seed<K>/runs.csv   seed K's own one-seed report (K >= 2; the report writes runs.csv since a318b35)

usage: python -m ddfbench.report.pool_seeds reports/gan_epochs_tuned [--model gan_sdf_tuned] > .../pooled.md
Prints a markdown table: mean ± std [95 % t interval] over the seeds (ddfbench.report.stats), and the
per-seed values.
"""

from __future__ import annotations

import argparse
import glob
import math
import os
import sys

import pandas as pd

from ddfbench.core.errors import InputError
from ddfbench.report.stats import summarize_values

# (column, label, scale)
COLUMNS = [("chamfer_l2", "CD-L2 ×10³", 1e3), ("p2s_chamfer_l2", "p2s CD-L2 ×10³", 1e3),
           ("fscore@0.005", "F@0.005", 1.0), ("fscore@0.01", "F@0.01", 1.0),
           ("level_offset", "level offset ×10³ (+out)", 1e3), ("closed", "closed", 1.0),
           ("components", "components", 1.0), ("steps", "steps", 1.0), ("epochs", "epochs", 1.0),
           ("fit_s", "fit s", 1.0)]


def _table_row(path: str, model: str, n: int) -> pd.Series:
    table = pd.read_csv(path)
    rows = table[table["model"] == model]
    if len(rows) != 1 or int(rows.iloc[0]["n"]) != n:
        raise InputError(f"{path}: must hold one row of {model} with n = {n}")
    return rows.iloc[0]


def first_two_seeds(folder: str, model: str) -> list[dict[str, float]]:
    """Seeds 0 and 1, {column: value} each: seed 0 from seed0/table.csv, seed 1 = 2 × the pair's mean − seed 0.
    Seed 0 must be one of the pair's runs (by key) and lie std/√2 from the pair's mean in every column."""
    pair = _table_row(os.path.join(folder, "table.csv"), model, 2)
    path = os.path.join(folder, "seed0", "table.csv")
    first = _table_row(path, model, 1)
    if str(first["keys"]) not in str(pair["keys"]).split():
        raise InputError(f"{path}: its run {first['keys']} is not one of table.csv's two ({pair['keys']})")
    seed0 = {column: float(first[f"{column}_mean"]) for column, _, _ in COLUMNS}
    off = [column for column, _, _ in COLUMNS if not math.isclose(
        abs(seed0[column] - float(pair[f"{column}_mean"])), float(pair[f"{column}_std"]) / math.sqrt(2),
        rel_tol=1e-6, abs_tol=1e-12)]
    if off:
        raise InputError(f"{path}: {', '.join(off)} not std/√2 from table.csv's two-seed mean")
    return [seed0, {column: 2 * float(pair[f"{column}_mean"]) - seed0[column] for column, _, _ in COLUMNS}]


def later_seeds(folder: str, model: str) -> list[pd.Series]:
    """Each seed<K>/ report's one finished run of model (K >= 2), in seed order."""
    rows = []
    for path in glob.glob(os.path.join(folder, "seed*", "runs.csv")):
        runs = pd.read_csv(path)
        runs = runs[(runs["model"] == model) & (runs["status"] == "ok")]
        name = os.path.basename(os.path.dirname(path))
        if len(runs) != 1 or name != f"seed{int(runs.iloc[0]['seed'])}" or int(runs.iloc[0]["seed"]) < 2:
            raise InputError(f"{path}: must hold one finished run of the seed its folder names, 2 or above")
        rows.append(runs.iloc[0])
    return sorted(rows, key=lambda row: int(row["seed"]))


def pooled_table(folder: str, model: str, title: str) -> str:
    """The markdown table: a title line, then per column mean ± std [interval] and each seed's value."""
    later = later_seeds(folder, model)
    seeds = first_two_seeds(folder, model) + [dict(row) for row in later]
    numbers = [0, 1] + [int(row["seed"]) for row in later]
    lines = [f"# {model}{title}: seeds {', '.join(map(str, numbers))} pooled (ddfbench.report.pool_seeds; seed 1 "
             "is 2 × the two-seed mean − seed 0)\n",
             f"| metric | mean ± std [95 % t interval], n = {len(seeds)} | "
             + " | ".join(f"seed {k}" for k in numbers) + " |",
             "|---|---|" + "---|" * len(seeds)]
    for column, label, scale in COLUMNS:
        values = [float(seed[column]) * scale for seed in seeds]
        s = summarize_values(values)
        lines.append(f"| {label} | {s.mean:.4g} ± {s.std:.2g} [{s.lo:.4g}, {s.hi:.4g}] | "
                     + " | ".join(f"{v:.4g}" for v in values) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ddfbench.report.pool_seeds", description=__doc__.split("\n")[0])
    parser.add_argument("folder", help="report folder with table.csv (seeds 0-1), seed0/table.csv and seed<K>/runs.csv")
    parser.add_argument("--model", default="gan_sdf_tuned")
    parser.add_argument("--title", default=" at 40 epochs on the bunny (code 332b432)",
                        help="words after the model in the title")
    args = parser.parse_args(argv)
    try:
        print(pooled_table(args.folder, args.model, args.title), end="")
    except InputError as exc:
        print(f"ddfbench.report.pool_seeds: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
