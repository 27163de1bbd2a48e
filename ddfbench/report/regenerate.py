"""`python -m ddfbench.report.regenerate [--only E1,E2] [--results DIR] [--reports DIR] [-- OVERRIDE ...]`
`python -m ddfbench.report.regenerate --from-records [--reports DIR] [--check]`

--from-records rebuilds every report below --reports that holds its compact records (records.jsonl.gz) from
those alone, with the options it was written with (report_options.json), every re-measurement's tables from
its measured rows (measured.jsonl.gz, ddfbench.report.measured) and every tuning study's from its trials table
and study.json (ddfbench.report.tune); then <reports>/claims.md from the records
(ddfbench.report.claims), <reports>/index.md (every report folder with its commit and whether it regenerates,
ddfbench.report.index) and the verdict table (reports/verdict.md and the README's block, ddfbench.report.verdict),
running no fit and measuring nothing. --check writes into a scratch folder instead and exits 1 naming each committed
file that differs, byte for byte, from its rebuild (text files: .md, .csv, .tex; the images are not drawn, those
committed are linked; sweep_status.md is the state of the machine that ran the sweep). CI runs --check.

Without --from-records:

Regenerates the committed reports: for each experiment (default: tune, ablation, sampling, representations,
storage, render_time, render_shapes, render_matched, pareto, convergence, paper_ddf) runs `python -m ddfbench +experiment=<e> out_dir=<results> [OVERRIDE ...]`
(tune: once per model that declares a search space, report by ddfbench.report.tune)
(finished runs are skipped, so an interrupted regeneration resumes), then writes
`python -m ddfbench.report <results>/<e> --out <reports>/<e>` (render_matched's comparison at matched accuracy with
render_time's DDF is a row of claims.md, ddfbench.report.matched). With overrides the report's first line
says "reduced budget: <overrides>" (or --note), so a report of a scaled run says how it was scaled.
The wall time of each sweep is printed and written to <reports>/<e>/wall_time.txt. Last, the paper
claims table <reports>/claims.md is rebuilt from every experiment's records (ddfbench.report.claims).
A report comes from one code commit: records resumed across a code change are refused (start a fresh
--results folder after changing the code).
"""

from __future__ import annotations

import argparse
import filecmp
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

from ddfbench.core import plugins
from ddfbench.core.errors import InputError, first_line, one_line
from ddfbench.fit import tune
from ddfbench.report import compact, index, measured, shape_suite, verdict
from ddfbench.report import tune as tune_report
from ddfbench.report.__main__ import OPTIONS_FILE, STATUS_FILE, MixedCommits, write_report_whole
from ddfbench.report.claims import write_claims, write_committed_claims

EXPERIMENTS = ("tune", "ablation", "sampling", "representations", "storage", "render_time", "render_shapes",
               "render_matched", "pareto", "convergence", "paper_ddf")


def sweep_commands(experiment: str, results: str, overrides: list[str]) -> list[list[str]]:
    """The command lines that run one experiment's sweep into results/<experiment>: one, or for `tune`
    per model that declares a search space its Optuna study and one run of its preset at the same budget."""
    base = [sys.executable, "-m", "ddfbench", f"+experiment={experiment}", f"out_dir={results}", "quiet=true"]
    if experiment == tune.EXPERIMENT:
        return [cmd for m in plugins.members("model", tune.EXPERIMENT)
                for cmd in ([*base, f"model={m}", *overrides], [*base, f"model={m}", "hydra.mode=RUN", *overrides])]
    return [[*base, *overrides]]


def regenerate(experiment: str, results: str, reports: str, overrides: list[str], note: str | None,
               run: bool = True) -> int:
    """Run one experiment (unless run=False) and write its report; return the sweep's exit code."""
    rc, seconds = 0, None
    commands = sweep_commands(experiment, results, overrides)
    if run:
        t0 = time.perf_counter()
        for cmd in commands:
            print("$", " ".join(cmd[1:]), flush=True)
            rc = max(rc, subprocess.run(cmd).returncode)
        seconds = time.perf_counter() - t0
    out = os.path.join(reports, experiment)
    if overrides and note is None:
        note = "reduced budget: " + " ".join(overrides)
    if experiment == tune.EXPERIMENT:
        rc = max(rc, tune_report.main([os.path.join(results, experiment), "--out", out]))
    else:
        try:  # staged beside the report folder: one that fails midway (a full disk) leaves the old report whole
            os.makedirs(out, exist_ok=True)
            write_report_whole(os.path.join(results, experiment), out, note=note,
                               sweep=[f"+experiment={experiment}", *overrides])
        except (MixedCommits, InputError, OSError) as exc:  # resumed across a code change, a sweep that left no record
            print(f"{experiment}: no report: {_said(exc)}", file=sys.stderr, flush=True)
            return 2
    if seconds is not None:
        with open(os.path.join(out, "wall_time.txt"), "w") as fh:
            fh.writelines(f"{seconds:.0f} s in all  {' '.join(cmd[1:])}\n" for cmd in commands)
        print(f"{experiment}: sweep exit {rc}, {seconds:.0f} s wall; report in {out}", flush=True)
    return rc


COMPARED = (".md", ".csv", ".tex")  # what --check compares byte for byte


def _said(exc: Exception) -> str:
    """An error as one line: an OSError's (errno text and file), else its own message (InputError's is one line)."""
    return one_line(exc) if isinstance(exc, OSError) else str(exc)


def reports_with_records(reports: str) -> list[str]:
    """Every folder below reports (any depth) that holds a compact records file, sorted."""
    return compact.folders_holding(reports, compact.FILE)


def rebuild(folder: str, into: str, draw: bool = True) -> None:
    """Write the report of folder's compact records into `into`, with the options it was written with (draw=False:
    no image drawn, those `into` holds linked), staged (write_report_whole): a rebuild that fails midway leaves `into`
    as it was."""
    options: dict = {}  # a compact file written by report.compact alone: the report's defaults
    path = os.path.join(folder, OPTIONS_FILE)
    if os.path.isfile(path):
        try:
            with open(path, encoding="utf-8") as fh:
                options = json.load(fh)
        except (OSError, ValueError) as exc:  # cut short, not JSON, not UTF-8: one line naming it
            raise InputError(f"{path}: not a readable JSON file ({first_line(exc)})") from None
        if not isinstance(options, dict):
            raise InputError(f"{path}: holds a JSON {type(options).__name__}, not an object of the report's options")
        for key, kind in (("note", str), ("plots", list)):
            if options.get(key) is not None and not isinstance(options[key], kind):
                raise InputError(f"{path}: {key} is a {type(options[key]).__name__}, not a {kind.__name__} or null")
    kinds = tuple(options["plots"]) if options.get("plots") is not None else None
    write_report_whole(os.path.join(folder, compact.FILE), into, note=options.get("note"), kinds=kinds,
                       allow_mixed_commits=bool(options.get("allow_mixed_commits")), draw=draw)


def differences(committed: str, rebuilt: str, whole: bool = False) -> list[str]:
    """The text files (COMPARED) the rebuild wrote that differ from the committed ones or are not committed, by
    name (other files of the folder, such as a README.md or another tool's table, are not the report's); whole: the
    rebuild writes the whole folder (a re-measurement's), so a committed text file it did not write differs too,
    but for its README.md (written by hand, about the folder)."""
    names = {f for f in os.listdir(rebuilt) if f.endswith(COMPARED) and f != STATUS_FILE}
    if whole:
        names |= {f for f in os.listdir(committed) if f.endswith(COMPARED) and f != "README.md"}
    return sorted(n for n in names if not (os.path.isfile(os.path.join(committed, n))
                                           and os.path.isfile(os.path.join(rebuilt, n))
                                           and filecmp.cmp(os.path.join(committed, n), os.path.join(rebuilt, n),
                                                           shallow=False)))


def from_records(reports: str, check: bool, readme: str | None = None) -> int:
    """--from-records: rebuild (or, with check, compare) every report below reports that has its records, and the
    verdict table (reports/verdict.md and the block of `readme`, when it has the markers)."""
    if os.path.isfile(os.path.join(reports, compact.FILE)):  # claims.md and index.md would land in a report
        print(f"ddfbench.report.regenerate: --reports {reports}: holds one report's records itself; give the folder of "
              "the reports (reports)", file=sys.stderr)
        return 2
    folders = reports_with_records(reports)
    remeasured = [f for f in measured.folders(reports) if f not in folders]  # a report's records come first
    studies = [f for f in tune_report.folders(reports) if f not in folders + remeasured]
    if not folders and not remeasured and not studies:
        print(f"ddfbench.report.regenerate: no {compact.FILE}, {measured.FILE} or {tune_report.STUDY_FILE} below "
              f"{reports}", file=sys.stderr)
        return 2
    differing, unreadable = [], 0
    for folder in folders + remeasured + studies:
        rows = folder not in folders  # a re-measurement's or a study's: the rebuild writes the whole folder
        remake = (measured.rebuild if folder in remeasured
                  else (lambda src, into: tune_report.rebuild(src, into, draw=not check)) if folder in studies
                  else (lambda src, into: rebuild(src, into, draw=not check)))
        try:
            if not check:
                remake(folder, folder)
                print(f"rebuilt {folder}", flush=True)
                continue
            with tempfile.TemporaryDirectory() as scratch:
                # kept, not compared: the images; an input: the suite's measured tags (read, not rewritten)
                for name in (f for f in os.listdir(folder)
                             if f.endswith((".png", ".pdf")) or f == shape_suite.TAGS_FILE):
                    shutil.copy2(os.path.join(folder, name), scratch)
                remake(folder, scratch)
                differing += [os.path.join(folder, name) for name in differences(folder, scratch, whole=rows)]
        except (InputError, MixedCommits, OSError) as exc:  # a damaged input, a full or read-only disk: the folder
            unreadable += 1                                     # stays as it was
            message = f"{folder}: not rebuilt ({_said(exc)})" if isinstance(exc, OSError) else _said(exc)
            print(f"ddfbench.report.regenerate: {message}", file=sys.stderr, flush=True)
    generated = {"claims.md": lambda path: write_committed_claims(reports, path),  # the files made from all reports
                 index.FILE: lambda path: index.write_index(reports, path)}
    for name, write in generated.items():
        path = os.path.join(reports, name)
        try:  # a damaged records file (named above) leaves the file as it was: one line, exit 2
            if not check:
                write(path)
                print(f"rebuilt {path}", flush=True)
            elif os.path.isfile(path):  # a reports folder without one (a scratch folder) has none to check
                with tempfile.TemporaryDirectory() as scratch:
                    write(os.path.join(scratch, name))
                    if not filecmp.cmp(path, os.path.join(scratch, name), shallow=False):
                        differing.append(path)
        except (InputError, OSError) as exc:
            unreadable += 1
            print(f"ddfbench.report.regenerate: {path} not rebuilt: {_said(exc)}", file=sys.stderr, flush=True)
    for path in differing:
        print(f"ddfbench.report.regenerate: {path} differs from its rebuild from its records", file=sys.stderr)
    if check:
        print(f"checked {len(folders)} report(s) with records, {len(remeasured)} re-measurement(s) with their "
              f"measured rows and {len(studies)} tuning stud{'y' if len(studies) == 1 else 'ies'} with their trial "
              f"tables: {len(differing)} file(s) differ", flush=True)
    code = 2 if unreadable else 1 if differing else 0
    if readme and os.path.isfile(readme) and verdict.START in open(readme).read():  # the README's generated block
        code = max(code, verdict.main(["--reports", reports, "--readme", readme, *(["--check"] if check else [])]))
    return code


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    overrides = argv[argv.index("--") + 1:] if "--" in argv else []
    argv = argv[: argv.index("--")] if "--" in argv else argv
    parser = argparse.ArgumentParser(prog="python -m ddfbench.report.regenerate", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", help=f"comma-separated experiments (default: {','.join(EXPERIMENTS)})")
    parser.add_argument("--results", default="results", help="out_dir of the runs (default: results)")
    parser.add_argument("--reports", default="reports", help="report folder (default: reports)")
    parser.add_argument("--note", help="first line of each report (default with overrides: 'reduced budget: ...')")
    parser.add_argument("--report-only", action="store_true", help="write the reports from existing records only")
    parser.add_argument("--from-records", action="store_true",
                        help=f"rebuild every report below --reports from its {compact.FILE}, every "
                             f"re-measurement from its {measured.FILE} and every tuning study from its "
                             f"{tune_report.TRIALS_FILE} and {tune_report.STUDY_FILE}, running and measuring nothing")
    parser.add_argument("--readme", help="README whose verdict block --from-records rebuilds (default: the README.md "
                                         "beside the --reports folder)")
    parser.add_argument("--check", action="store_true",
                        help="with --from-records: compare the rebuilds with the committed files, exit 1 on a difference")
    args = parser.parse_args(argv)
    if args.check and not args.from_records:
        parser.error("--check goes with --from-records")
    if args.from_records:
        readme = args.readme or os.path.join(os.path.dirname(os.path.abspath(args.reports)), "README.md")
        return from_records(args.reports, args.check, readme)
    experiments = args.only.split(",") if args.only else list(EXPERIMENTS)
    conf = os.path.join(plugins.CONF_DIR, "experiment")
    unknown = [e for e in experiments if not os.path.isfile(os.path.join(conf, f"{e}.yaml"))]
    if unknown:
        print(f"ddfbench.report.regenerate: --only {','.join(unknown)}: no conf/experiment/<name>.yaml", file=sys.stderr)
        return 2
    codes = [regenerate(e, args.results, args.reports, overrides, args.note, run=not args.report_only)
             for e in experiments]
    try:
        write_claims(args.results, os.path.join(args.reports, "claims.md"))
        print(f"claims: {os.path.join(args.reports, 'claims.md')}", flush=True)
    except InputError as exc:  # none of the claims' experiments below --results (e.g. --only tune)
        print(f"claims: not written ({exc})", flush=True)
    return max(codes, default=0)


if __name__ == "__main__":
    sys.exit(main())
