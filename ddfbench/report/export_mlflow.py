"""`python -m ddfbench.report.export_mlflow results/<experiment> [--uri URI] [--experiment NAME]`

Backfills run records already on disk into MLflow (needs `pip install -e ".[tracking]"`), one MLflow
run per record, exactly as `tracking=mlflow` logs a new run (ddfbench/tracking.py). Idempotent: a
record already logged (same key and finish time) is left alone, so running it again adds nothing.
Default store: sqlite:///<out_dir>/mlflow.db, out_dir being the folder that holds the experiment
folders (results/ for results/<experiment>/<key>/record.json).
"""

from __future__ import annotations

import argparse
import os
import sys

from ddfbench import tracking
from ddfbench.runs import find_records


def out_dir_of(run_dir: str) -> str:
    """results/<experiment>/<key> → results."""
    return os.path.dirname(os.path.dirname(os.path.normpath(run_dir)))


def export(records_dir: str, uri: str | None = None, experiment: str | None = None) -> tuple[int, int]:
    """Log every record below records_dir; return (runs logged now, records already there).
    Raises what MLflow raises: a backfill is asked for, so a failure ends it with an error."""
    logged = present = 0
    for record in find_records(records_dir):
        run_dir = record.pop("_dir")
        target = uri or tracking.default_uri(out_dir_of(run_dir))
        with tracking.bounded_and_quiet(10.0, 0):
            run_id = tracking.log_record(record, run_dir, target, experiment)
        logged, present = (logged + 1, present) if run_id else (logged, present + 1)
    return logged, present


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ddfbench.report.export_mlflow", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("records", help="folder of run records, e.g. results/representations")
    parser.add_argument("--uri", help="MLflow tracking URI (default: sqlite:///<out_dir>/mlflow.db)")
    parser.add_argument("--experiment", help="MLflow experiment name (default: each record's experiment)")
    args = parser.parse_args(argv)
    if not os.path.isdir(args.records):
        print(f"export_mlflow: {args.records}: no such folder of run records", file=sys.stderr)
        return 2
    try:
        logged, present = export(args.records, args.uri, args.experiment)
    except ImportError:
        print('export_mlflow: mlflow is not installed (pip install -e ".[tracking]")', file=sys.stderr)
        return 2
    except Exception as exc:
        first = (str(exc).strip().splitlines() or [""])[0]
        print(f"export_mlflow: {args.uri or 'sqlite store'}: {type(exc).__name__}: {first}", file=sys.stderr)
        return 1
    print(f"export_mlflow: {logged} runs logged, {present} already in MLflow")
    return 0


if __name__ == "__main__":
    sys.exit(main())
