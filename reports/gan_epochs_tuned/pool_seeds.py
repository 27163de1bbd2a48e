"""Three-seed summary of `gan_sdf_tuned` at the thesis' 40 epochs, pooled from two committed reports of
the same code (332b432), because the records of seeds 0-1 went with the machine that ran them:

  table.csv         the two-seed report (seeds 0 and 1): for n = 2 the two values of a column are
                    mean - std/sqrt(2) and mean + std/sqrt(2) (which seed is which does not change a pool)
  seed2/runs.csv    seed 2's own run row (the report writes runs.csv since a318b35)

usage (from the repository root): python reports/gan_epochs_tuned/pool_seeds.py > reports/gan_epochs_tuned/pooled.md
Prints a markdown table: mean ± std [95 % t interval] over the 3 seeds (ddfbench.report.stats), and the
per-seed values.
"""

from __future__ import annotations

import math
import os

import pandas as pd

from ddfbench.report.stats import summarize_values

HERE = os.path.dirname(os.path.abspath(__file__))
# (column, label, scale)
COLUMNS = [("chamfer_l2", "CD-L2 ×10³", 1e3), ("p2s_chamfer_l2", "p2s CD-L2 ×10³", 1e3),
           ("fscore@0.005", "F@0.005", 1.0), ("fscore@0.01", "F@0.01", 1.0),
           ("level_offset", "level offset ×10³ (+out)", 1e3), ("closed", "closed", 1.0),
           ("components", "components", 1.0), ("steps", "steps", 1.0), ("epochs", "epochs", 1.0),
           ("fit_s", "fit s", 1.0)]


def two_seed_values(table: pd.DataFrame, column: str) -> list[float]:
    """The two per-seed values behind a row of n = 2: mean ∓ std/√2."""
    row = table[table["model"] == "gan_sdf_tuned"].iloc[0]
    assert int(row["n"]) == 2, "the two-seed table must hold n = 2"
    mean, std = float(row[f"{column}_mean"]), float(row[f"{column}_std"])
    return [mean - std / math.sqrt(2), mean + std / math.sqrt(2)]


def main() -> None:
    table = pd.read_csv(os.path.join(HERE, "table.csv"))
    seed2 = pd.read_csv(os.path.join(HERE, "seed2", "runs.csv"))
    seed2 = seed2[(seed2["model"] == "gan_sdf_tuned") & (seed2["status"] == "ok")].iloc[0]
    assert int(seed2["seed"]) == 2, "seed2/runs.csv must hold seed 2"
    print("# gan_sdf_tuned at 40 epochs on the bunny: seeds 0-2 pooled (pool_seeds.py; code 332b432)\n")
    print("| metric | mean ± std [95 % t interval], n = 3 | seeds 0-1, low and high (from table.csv) | seed 2 |")
    print("|---|---|---|---|")
    for column, label, scale in COLUMNS:
        pair = [v * scale for v in two_seed_values(table, column)]
        third = float(seed2[column]) * scale
        s = summarize_values(pair + [third])
        print(f"| {label} | {s.mean:.4g} ± {s.std:.2g} [{s.lo:.4g}, {s.hi:.4g}] | "
              f"{pair[0]:.4g}, {pair[1]:.4g} | {third:.4g} |")


if __name__ == "__main__":
    main()
