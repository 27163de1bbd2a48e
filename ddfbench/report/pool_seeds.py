"""One model's figures over every seed run so far, pooled from the per-run tables (runs.csv) of one report folder
and its seed<K>/ subfolders, where the seeds were fit in several sessions and reported as they finished
(reports/gan_epochs_tuned: gan_sdf_tuned at the thesis' 40 epochs, code 332b432):

  runs.csv           the folder's own report (there: seeds 0-3)
  seed<K>/runs.csv   seed K's own one-seed report

usage: python -m ddfbench.report.pool_seeds reports/gan_epochs_tuned [--model gan_sdf_tuned] > .../pooled.md
Prints a markdown table: mean ± std [95 % t interval] over the seeds (ddfbench.report.stats), and the
per-seed values. A seed found in two tables, or a seed<K>/ report of another seed, is a one-line error.
"""

from __future__ import annotations

import argparse
import glob
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


def _finished(path: str, model: str) -> list[tuple[int, str, pd.Series]]:
    """(seed, path, row) of each finished run of model in one runs.csv; a one-line InputError naming the file where
    it is not a report's runs.csv (missing, unparsable, without the columns pooled, a seed that is not a number)."""
    need = ["model", "status", "seed", *(column for column, _, _ in COLUMNS)]
    try:
        runs = pd.read_csv(path)
        missing = [column for column in need if column not in runs.columns]
        if missing:
            raise ValueError(f"no column {', '.join(missing)}")
        done = runs[(runs["model"] == model) & (runs["status"] == "ok")]
        return [(int(row["seed"]), path, row) for _, row in done.iterrows()]
    except (OSError, ValueError) as exc:
        why = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise InputError(f"{path}: not a report's runs.csv ({why})") from None


def seeds(folder: str, model: str) -> list[pd.Series]:
    """Every finished run of model in folder/runs.csv and in each folder/seed<K>/runs.csv (there one finished run,
    of seed K), in seed order; each seed once, and at least one."""
    runs = _finished(os.path.join(folder, "runs.csv"), model)
    for sub in sorted(glob.glob(os.path.join(folder, "seed*", ""))):
        path = os.path.join(sub, "runs.csv")
        found = _finished(path, model)
        if len(found) != 1 or os.path.basename(os.path.dirname(path)) != f"seed{found[0][0]}":
            raise InputError(f"{path}: must hold one finished run of {model}, of the seed its folder names "
                             f"(holds {len(found)})")
        runs += found
    if not runs:
        raise InputError(f"{os.path.join(folder, 'runs.csv')}: no finished run of {model}")
    for seed in sorted({seed for seed, _, _ in runs}):
        paths = [path for k, path, _ in runs if k == seed]
        if len(paths) > 1:
            raise InputError(f"seed {seed} is pooled twice: in {', '.join(paths)}")
    return [row for _, _, row in sorted(runs, key=lambda run: run[0])]


def pooled_table(folder: str, model: str, title: str) -> str:
    """The markdown table: a title line, then per column mean ± std [interval] and each seed's value."""
    runs = seeds(folder, model)
    numbers = [int(row["seed"]) for row in runs]
    lines = [f"# {model}{title}: seeds {', '.join(map(str, numbers))} pooled (ddfbench.report.pool_seeds)\n",
             f"| metric | mean ± std [95 % t interval], n = {len(runs)} | "
             + " | ".join(f"seed {k}" for k in numbers) + " |",
             "|---|---|" + "---|" * len(runs)]
    for column, label, scale in COLUMNS:
        values = [float(run[column]) * scale for run in runs]
        s = summarize_values(values)
        lines.append(f"| {label} | {s.mean:.4g} ± {s.std:.2g} [{s.lo:.4g}, {s.hi:.4g}] | "
                     + " | ".join(f"{v:.4g}" for v in values) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ddfbench.report.pool_seeds", description=__doc__.split("\n")[0])
    parser.add_argument("folder", help="report folder with runs.csv and seed<K>/runs.csv")
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
