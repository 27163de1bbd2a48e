"""A re-measurement's rows travel with its tables, so its folder regenerates from the repository like a report.

The tools that measure finished runs again from their artifacts (ddfbench.report.reevaluate, zero_level,
edge_error: meshes, networks and renders, which stay with the runs) write, beside their tables:

- `measured.jsonl.gz`: every row the tool measured, in its order, one JSON object a line (zero_level: a row per
  run; edge_error: a row per run and band; reevaluate: each run record with its metrics measured again, the out_dir
  override written as `<out_dir>` as in compact records, and with --store-as each run as saved, measured alike,
  the rows without `_stored_as`); deterministic (gzip's timestamp 0); NaN and infinities as Python's json writes
  them (NaN, Infinity), numpy scalars as Python numbers;
- `measured.json`: {"tool", "command", "what", "provenance"}, the parts of the tables' first line
  (`command`: what, records of code …, measured by code ….).

The tool writes its text files (table.md, table.csv, runs.csv, paired.md) from these two files as they read back, so
`rebuild` (`regenerate --from-records`) writes the same bytes again on a fresh clone, measuring nothing; a tool's
tables are `write_tables(out, header, rows) -> table.md's text` of its module.
"""

from __future__ import annotations

import gzip
import importlib
import json
import os
import sys
from typing import Any

from ddfbench.core.errors import InputError
from ddfbench.report.checked_json import checked_json_object
from ddfbench.report.compact import folders_holding, portable, write_jsonl_gz
from ddfbench.run.runs import code_commits, code_sha

FILE = "measured.jsonl.gz"
META = "measured.json"
TOOLS = ("reevaluate", "zero_level", "edge_error")  # modules of ddfbench.report with write_tables
HEADER = ("tool", "command", "what", "provenance")


def header(tool: str, argv: list[str] | None, what: str, records: list[dict[str, Any]], results: str) -> dict[str, str]:
    """The parts of a table's first line: the command (the records folder `results` written as
    `<out_dir>/<its name>`: a folder of the machine that measured means nothing on a clone), what was measured, the
    records' code commits and the measuring code's."""
    portable_results = f"<out_dir>/{os.path.basename(os.path.normpath(results))}"
    args = [portable_results if arg == results else arg for arg in (argv if argv is not None else sys.argv[1:])]
    return {"tool": tool,
            "command": f"`python -m ddfbench.report.{tool} {' '.join(args)}`",
            "what": what,
            "provenance": f"records of code {', '.join(c[:7] for c in code_commits(records))}, "
                          f"measured by code {(code_sha() or 'unknown')[:7]}"}


def first_line(head: dict[str, str], what: str | None = None) -> str:
    """A table's first line from header's parts (`what` in place of the header's own, e.g. for a second table)."""
    return f"{head['command']}: {what or head['what']}, {head['provenance']}."


def _plain(value: Any) -> Any:
    """A numpy scalar as its Python number (json's `default`); anything else is not a row's value."""
    if hasattr(value, "item"):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not a measured value")


def write(out: str, head: dict[str, str], rows: list[dict[str, Any]]) -> str:
    """Write the rows and the header into `out`, then the tool's tables from them as read back; table.md's text."""
    os.makedirs(out, exist_ok=True)
    write_jsonl_gz((json.dumps(portable(row), default=_plain) for row in rows), os.path.join(out, FILE))
    with open(os.path.join(out, META), "w", encoding="utf-8") as fh:
        json.dump(head, fh, indent=1, ensure_ascii=False)
        fh.write("\n")
    return rebuild(out, out)


def publish(tool: str, out: str, head: dict[str, str], rows: list[dict[str, Any]], failed: int) -> int:
    """write() and print table.md, unless a run was unreadable and `out` holds a measurement already (a committed
    one is not replaced by part of one: one line instead); the tool's exit code (1 when a run was unreadable)."""
    if failed and os.path.isfile(os.path.join(out, FILE)):
        print(f"ddfbench.report.{tool}: {failed} run(s) unreadable: {out} holds a measurement and is kept as it was "
              "(write the rows measured now to a new --out)", file=sys.stderr)
        return 1
    print(write(out, head, rows), end="")
    return 1 if failed else 0


def read(folder: str) -> tuple[dict[str, str], list[dict[str, Any]]]:
    """The header and rows a re-measurement folder holds; InputError naming the file (and line) that is not one."""
    path = os.path.join(folder, META)
    head = checked_json_object(path, dict.fromkeys(HEADER, str))
    if head["tool"] not in TOOLS:
        raise InputError(f"{path}: tool {head['tool']!r} is not one of {TOOLS}")
    path, rows = os.path.join(folder, FILE), []
    try:
        with gzip.open(path, "rt", encoding="utf-8") as fh:
            for number, line in enumerate(fh, 1):
                row = json.loads(line)
                if not isinstance(row, dict):
                    raise ValueError(f"line {number} is a JSON {type(row).__name__}, not an object")
                rows.append(row)
    except (OSError, EOFError, ValueError) as exc:
        raise InputError(f"{path}: not measured rows ({exc})") from exc
    return head, rows


def rebuild(folder: str, into: str) -> str:
    """Write the tables of folder's measured rows into `into` with the tool that measured them; table.md's text."""
    head, rows = read(folder)
    os.makedirs(into, exist_ok=True)
    return importlib.import_module(f"ddfbench.report.{head['tool']}").write_tables(into, head, rows)


def holds_rows(folder: str) -> bool:
    """Whether folder holds a re-measurement's rows and header (both files)."""
    return all(os.path.isfile(os.path.join(folder, name)) for name in (FILE, META))


def folders(reports: str) -> list[str]:
    """Every folder below reports (any depth) that holds measured rows, sorted."""
    return folders_holding(reports, FILE, META)
