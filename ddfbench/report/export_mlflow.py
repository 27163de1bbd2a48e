"""Backfill MLflow from existing run records (needs the `tracking` extra).

    python -m ddfbench.report.export_mlflow results/ablation                 # into sqlite:///results/mlflow.db
    python -m ddfbench.report.export_mlflow results/ablation --uri http://host:5000

Every record.json below the folder becomes one MLflow run (ddfbench.run.tracking.log_record); records
already logged (same key and status) are left alone, so running it twice adds nothing.
"""

from __future__ import annotations

import argparse
import os
import sys

from ddfbench.core.errors import InputError, one_line
from ddfbench.run.runs import find_records
from ddfbench.run.tracking import default_uri, log_record


def export(records_dir: str, uri: str) -> tuple[int, int]:
    """Log every record below records_dir to uri; return (logged, already there). The first record that cannot be
    logged (a missing artifact, a store that refuses the URI) is a one-line InputError naming it; the runs logged
    before it stay, and the next export logs the rest."""
    logged = present = 0
    for record in find_records(records_dir):
        run_dir = record.pop("_dir")
        try:
            run_id = log_record(uri, record, run_dir)
        except ImportError:
            raise
        except Exception as exc:
            raise InputError(f"{uri}: run {run_dir} not logged ({one_line(exc)}); {logged} logged before it, "
                             f"{present} already there") from None
        logged, present = logged + (run_id is not None), present + (run_id is None)
    return logged, present


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ddfbench.report.export_mlflow", description=__doc__.splitlines()[0])
    ap.add_argument("records_dir", help="a folder of run records, e.g. results/<experiment>")
    ap.add_argument("--uri", help="MLflow tracking URI (default: sqlite:///<parent of records_dir>/mlflow.db)")
    args = ap.parse_args(argv)
    if not os.path.isdir(args.records_dir):
        print(f"export_mlflow: {args.records_dir}: not a folder", file=sys.stderr)
        return 2
    uri = args.uri or default_uri(os.path.dirname(os.path.abspath(args.records_dir)))
    try:
        logged, present = export(args.records_dir, uri)
    except ImportError:
        print('export_mlflow: mlflow is not installed (pip install -e ".[tracking]")', file=sys.stderr)
        return 2
    except InputError as exc:
        print(f"export_mlflow: {exc}", file=sys.stderr)
        return 2
    if not logged + present:
        print(f"export_mlflow: {args.records_dir}: no run records below it", file=sys.stderr)
        return 2
    print(f"{uri}: {logged} runs logged, {present} already there")
    return 0


if __name__ == "__main__":
    sys.exit(main())
