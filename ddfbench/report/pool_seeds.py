"""One model's figures over every seed run so far, pooled from the committed reports of one folder, where the
records of the first two seeds went with the machine that ran them (reports/gan_epochs_tuned: gan_sdf_tuned at
the thesis' 40 epochs, code 332b432):

  table.csv         the two-seed report (seeds 0 and 1): for n = 2 the two values of a column are
                    mean - std/sqrt(2) and mean + std/sqrt(2) (which seed is which is lost; a pool does not need it)
  seed<K>/runs.csv  seed K's own one-seed report (K >= 2; the report writes runs.csv since a318b35)

usage: python -m ddfbench.report.pool_seeds reports/gan_epochs_tuned [--model gan_sdf_tuned] > .../pooled.md
Prints a markdown table: mean ± std [95 % t interval] over the seeds (ddfbench.report.stats), and the
per-seed values.
"""

from __future__ import annotations

import argparse
import glob
import math
import os

import pandas as pd

from ddfbench.report.stats import summarize_values

# (column, label, scale)
COLUMNS = [("chamfer_l2", "CD-L2 ×10³", 1e3), ("p2s_chamfer_l2", "p2s CD-L2 ×10³", 1e3),
           ("fscore@0.005", "F@0.005", 1.0), ("fscore@0.01", "F@0.01", 1.0),
           ("level_offset", "level offset ×10³ (+out)", 1e3), ("closed", "closed", 1.0),
           ("components", "components", 1.0), ("steps", "steps", 1.0), ("epochs", "epochs", 1.0),
           ("fit_s", "fit s", 1.0)]


def two_seed_values(table: pd.DataFrame, model: str, column: str) -> list[float]:
    """The two per-seed values behind model's row of n = 2: mean ∓ std/√2."""
    row = table[table["model"] == model].iloc[0]
    assert int(row["n"]) == 2, "the two-seed table must hold n = 2"
    mean, std = float(row[f"{column}_mean"]), float(row[f"{column}_std"])
    return [mean - std / math.sqrt(2), mean + std / math.sqrt(2)]


def later_seeds(folder: str, model: str) -> list[pd.Series]:
    """Each seed<K>/ report's one finished run of model, in seed order."""
    rows = []
    for path in glob.glob(os.path.join(folder, "seed*", "runs.csv")):
        runs = pd.read_csv(path)
        runs = runs[(runs["model"] == model) & (runs["status"] == "ok")]
        folder = os.path.basename(os.path.dirname(path))
        assert len(runs) == 1 and folder == f"seed{int(runs.iloc[0]['seed'])}", \
            f"{path} must hold one finished run of the seed its folder names"
        rows.append(runs.iloc[0])
    return sorted(rows, key=lambda row: int(row["seed"]))


def pooled_table(folder: str, model: str, title: str) -> str:
    """The markdown table: a title line, then per column mean ± std [interval], seeds 0-1 and each later seed."""
    table = pd.read_csv(os.path.join(folder, "table.csv"))
    later = later_seeds(folder, model)
    names = [f"seed {int(row['seed'])}" for row in later]
    n = 2 + len(later)
    lines = [f"# {model}{title}: seeds 0-1 and {', '.join(str(int(r['seed'])) for r in later)} pooled "
             "(ddfbench.report.pool_seeds)\n"]
    lines.append(f"| metric | mean ± std [95 % t interval], n = {n} | seeds 0-1, low and high (from table.csv) | "
                 + " | ".join(names) + " |")
    lines.append("|---|---|---|" + "---|" * len(later))
    for column, label, scale in COLUMNS:
        pair = [v * scale for v in two_seed_values(table, model, column)]
        rest = [float(row[column]) * scale for row in later]
        s = summarize_values(pair + rest)
        lines.append(f"| {label} | {s.mean:.4g} ± {s.std:.2g} [{s.lo:.4g}, {s.hi:.4g}] | "
                     f"{pair[0]:.4g}, {pair[1]:.4g} | " + " | ".join(f"{v:.4g}" for v in rest) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m ddfbench.report.pool_seeds", description=__doc__.split("\n")[0])
    parser.add_argument("folder", help="report folder with table.csv (seeds 0-1) and seed<K>/runs.csv")
    parser.add_argument("--model", default="gan_sdf_tuned")
    parser.add_argument("--title", default=" at 40 epochs on the bunny (code 332b432)",
                        help="words after the model in the title")
    args = parser.parse_args(argv)
    print(pooled_table(args.folder, args.model, args.title), end="")


if __name__ == "__main__":
    main()
