"""`python -m ddfbench.report results/<experiment> [--out reports/<experiment>]`: tables from run records."""

from __future__ import annotations

import argparse
import os
import sys

from ddfbench.report.tables import summarize, to_csv, to_latex, to_markdown
from ddfbench.runs import find_records


def write_report(records_dir: str, out_dir: str) -> str:
    """Write table.md, table.csv and table.tex for the records below records_dir; return the markdown."""
    records = find_records(records_dir)
    df = summarize(records)
    os.makedirs(out_dir, exist_ok=True)
    md = to_markdown(df)
    with open(os.path.join(out_dir, "table.md"), "w") as fh:
        fh.write(md)
    with open(os.path.join(out_dir, "table.tex"), "w") as fh:
        fh.write(to_latex(df))
    to_csv(df, os.path.join(out_dir, "table.csv"))
    return md


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ddfbench.report", description=__doc__)
    parser.add_argument("records", help="folder of run records, e.g. results/ablation")
    parser.add_argument("--out", help="report folder (default: reports/<name of the records folder>)")
    args = parser.parse_args(argv)
    if not os.path.isdir(args.records):
        print(f"ddfbench.report: {args.records}: no such folder of run records", file=sys.stderr)
        return 2
    out = args.out or os.path.join("reports", os.path.basename(os.path.normpath(args.records)))
    print(write_report(args.records, out))
    print(f"wrote {out}/table.md, table.csv, table.tex")
    return 0


if __name__ == "__main__":
    sys.exit(main())
