"""Compact records: every run record a report was made from, in one gzip JSON-lines file beside the report
(records.jsonl.gz), so that the report regenerates from the repository alone, on a fresh clone, running no fit.

A compact record is the record.json as written (metrics, costs, fit curves and probes, config, environment), less
the run folder it was read from and with the machine's folder in its `out_dir=` override written as `<out_dir>` (as
the reports write it: a path of the machine that ran it means nothing on a clone), and a package sample's install
path in `shape.source` (records of code before the shapes wrote it so) as the package and file name, as records now
write it (`pymeshlab sample bunny.obj`); the run folder's artifacts
(meshes, renders, the model) stay behind, so what needs them (the gallery, the re-measuring tools) is not rebuilt
from this file. The file is deterministic: the
records sorted by (experiment, key), keys sorted, gzip's timestamp 0, so one set of records gives one file.

`python -m ddfbench.report.compact RESULTS/<experiment> OUT.jsonl.gz` writes one from a folder of run records;
`python -m ddfbench.report.compact --restore IN.jsonl.gz RESULTS` writes its records back as run records
(RESULTS/<experiment>/<key>/record.json, without their artifacts), so that a sweep cut short on another machine
resumes on this one: the runner skips every key with an ok record, and the report is written from all of them.
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
import re
import sys
from typing import IO, Any, Iterable

from ddfbench.core.atomic import write_atomic
from ddfbench.core.errors import InputError, one_line
from ddfbench.run.runs import find_records, record_path, record_problem, schema_problem, write_json_atomic

FILE = "records.jsonl.gz"
KEY = re.compile(r"[0-9a-f]{16}")  # runs.config_key
OUT_DIR = "out_dir="
SAMPLE = re.compile(r".*/site-packages/pymeshlab/tests/sample_meshes/(.+)$")  # truth.catalog's sample folder


def portable(rec: dict[str, Any]) -> dict[str, Any]:
    """The record less its run folder (`_dir`), its `out_dir=` override written as `out_dir=<out_dir>`, a pymeshlab
    sample's install path in `shape.source` as `pymeshlab sample <file>`."""
    row = {k: v for k, v in rec.items() if k != "_dir"}
    shape = row.get("shape")
    if isinstance(shape, dict) and isinstance(shape.get("source"), str) and (m := SAMPLE.match(shape["source"])):
        row["shape"] = {**shape, "source": f"pymeshlab sample {m.group(1)}"}
    if isinstance(row.get("overrides"), list):
        row["overrides"] = [f"{OUT_DIR}<out_dir>" if isinstance(o, str) and o.startswith(OUT_DIR) else o
                            for o in row["overrides"]]
    return row


def walk_visible(root: str) -> Iterable[tuple[str, list[str], list[str]]]:
    """os.walk(root) less the folders whose name starts with a dot (and all below them): a report's scratch folder
    (.report-*, write_report_whole) that a killed report left beside it holds a copy of its records, and is no
    report."""
    for folder, dirs, files in os.walk(root):
        dirs[:] = [d for d in dirs if not d.startswith(".")]
        yield folder, dirs, files


def folders_holding(root: str, *names: str) -> list[str]:
    """Every folder below root (any depth, root included; no hidden one, walk_visible) that holds every one of the
    named files, sorted."""
    return sorted(folder for folder, _, files in walk_visible(root) if all(name in files for name in names))


def write_jsonl_gz(lines: Iterable[str], path: str) -> str:
    """Write the lines (JSON texts) to path, one a line, gzip'd with timestamp 0 (one content, one file), whole or
    not at all (core.atomic); return path."""

    def write(raw: IO[bytes]) -> None:
        with gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0) as fh:
            for line in lines:
                fh.write((line + "\n").encode())

    return write_atomic(path, write, "wb")


def write_compact(records: list[dict[str, Any]], path: str) -> str:
    """Write the records (as find_records or read_compact give them) to path; return path."""
    rows = sorted((portable(r) for r in records),
                  key=lambda r: (str(r.get("experiment")), str(r.get("key"))))
    return write_jsonl_gz((json.dumps(row, sort_keys=True, allow_nan=False) for row in rows), path)


def read_compact(path: str, strict: bool = False) -> list[dict[str, Any]]:
    """The records of a compact file, each with `_dir` None (its run folder is not here). A line that is not a
    run record is left out with one stderr line naming the file and the line; with strict it is a one-line
    InputError (a damaged file that a report written from it would replace). A file gzip cannot read is one. A
    record of another schema (or none) is left out with a line, strict or not, as find_records leaves it out."""
    return _read_compact(path, strict)[0]


def _read_compact(path: str, strict: bool) -> tuple[list[dict[str, Any]], int]:
    """read_compact's records and how many lines it left out (not a record, or of another schema or none)."""
    out, left = [], 0
    try:
        with gzip.open(path, "rt", encoding="utf-8") as fh:
            for number, line in enumerate(fh, 1):
                try:
                    rec = json.loads(line)
                    problem = record_problem(rec) if isinstance(rec, dict) else f"a JSON {type(rec).__name__}"
                except json.JSONDecodeError as exc:
                    problem = f"not JSON ({exc.msg})"
                if problem and strict:
                    raise InputError(f"{path} line {number}: {problem}: a damaged compact file (nothing written; "
                                     "git checkout restores a committed one)")
                if not problem:  # no damage; another schema is left out, as find_records does
                    problem = schema_problem(rec)
                if problem:
                    left += 1
                    print(f"ddfbench: skipped {path} line {number}: {problem}", file=sys.stderr)
                    continue
                out.append({**rec, "_dir": None})
    except (OSError, EOFError, UnicodeDecodeError) as exc:  # not gzip, cut short, not UTF-8
        raise InputError(f"{path}: cannot be read as a compact file ({one_line(exc)})") from None
    return out, left


def records_of(folder: str) -> list[dict[str, Any]]:
    """The records of a report folder's compact file (FILE); [] where the folder holds none."""
    path = os.path.join(folder, FILE)
    return read_compact(path) if os.path.isfile(path) else []


def load_records(source: str, strict: bool = False) -> list[dict[str, Any]]:
    """The records of a folder of run records (any depth) or of a compact file (read_compact, strict)."""
    return read_compact(source, strict) if source.endswith(".jsonl.gz") else find_records(source)


def restore(path: str, out_dir: str) -> tuple[int, int, int]:
    """Write each ok record of the current schema in the compact file at path (what the runner skips) to
    out_dir/<experiment>/<key>/record.json, where that folder holds no record yet (a run of this machine is never
    replaced); return (written, kept, left out). A failed record, one of another schema or a damaged line
    (read_compact's line names it) is left out (its run goes again), as is one whose experiment or key is not a
    plain folder name, with one stderr line naming it."""
    from ddfbench.run.checks import SAFE_NAME  # the run folders' rule (checks imports the families: torch)

    records, left = _read_compact(path, strict=False)
    written = kept = 0
    for rec in records:
        experiment, key = rec["experiment"], rec["key"]
        if not (KEY.fullmatch(key) and SAFE_NAME.fullmatch(experiment) and ".." not in experiment):
            print(f"ddfbench: skipped {path}: experiment {experiment!r}, key {key!r} is not a run folder", file=sys.stderr)
            left += 1
            continue
        if rec.get("status") != "ok":
            left += 1
            continue
        target = record_path(out_dir, experiment, key)
        if os.path.exists(target):
            kept += 1
            continue
        write_json_atomic(target, {k: v for k, v in rec.items() if k != "_dir"})
        written += 1
    return written, kept, left


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ddfbench.report.compact", description=__doc__.split("\n")[0])
    parser.add_argument("records", help="folder of run records, e.g. results/default (with --restore: a compact file)")
    parser.add_argument("out", help=f"the compact file to write (conventionally <report folder>/{FILE}); with "
                                    "--restore: the out_dir to write its run records into")
    parser.add_argument("--restore", action="store_true",
                        help="write the compact file's records back into an out_dir, so that its sweep resumes")
    args = parser.parse_args(argv)
    if args.restore:
        if not os.path.isfile(args.records):
            print(f"ddfbench.report.compact: {args.records}: no such compact file", file=sys.stderr)
            return 2
        try:
            written, kept, left = restore(args.records, args.out)
        except InputError as exc:  # not gzip, cut short: nothing of it written
            print(f"ddfbench.report.compact: {exc}", file=sys.stderr)
            return 2
        except OSError as exc:  # a read-only or full out_dir: each record is written whole or not at all
            print(f"ddfbench.report.compact: {exc.filename or args.out}: cannot be written ({exc.strerror or exc}); "
                  "the records restored before it are whole: run the command again once it can be", file=sys.stderr)
            return 2
        print(f"restored {written} records into {args.out} ({kept} already there, kept; {left} failed, older, "
              "misnamed or damaged, left out: their runs go again)")
        return 0
    records = find_records(args.records)
    if not records:
        print(f"ddfbench.report.compact: {args.records}: no run records", file=sys.stderr)
        return 2
    try:
        print(f"wrote {len(records)} records to {write_compact(records, args.out)}")
    except OSError as exc:  # a read-only or full folder, a missing one: written whole or not at all
        print(f"ddfbench.report.compact: {args.out}: cannot be written ({exc.strerror or exc}): nothing written",
              file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
