"""`python -m ddfbench.report RECORDS [--out FOLDER] [--note TEXT] [--plots K,...]`

RECORDS is a folder of run records (results/<experiment>) or a compact file (<report>/records.jsonl.gz,
ddfbench.report.compact); the report goes to --out, by default beside the records (results/<experiment>/report,
or the compact file's own folder), so that a committed report changes only when --out names it. Writes:
  table.md, table.csv, table.tex   one row per configuration (ddfbench.report.tables)
  runs.csv                         one row per run record (tables.per_run): its key, seed and every metric,
                                   so a report keeps each seed's values after the records are gone
  <kind>.png, <kind>.pdf           the experiment's plots (ddfbench.report.plots: PLOTS_BY_EXPERIMENT)
  gallery.png                      renders beside the oracle's, error maps, meshes (ddfbench.report.gallery)
  report.md                        the note, the table, the plots, and every record key the table was built from
  records.jsonl.gz                 the records themselves, compact (ddfbench.report.compact): the report
                                   regenerates from them (python -m ddfbench.report.regenerate --from-records)
  report_options.json              the note and plot kinds the report was written with (for regeneration)
  sweep_status.md                  from a folder of records: the sweep's runs done / failed / missing
  time_to_floor.md, .csv           convergence: time to reach 2x and 5x the noise floor (report.convergence)
  stability.md, .csv               convergence: how many runs diverged (non-finite, empty mesh, regressed)
  probes.md, .csv                  convergence: every probe of every run (step, epoch, fit s, CD-L2, F-scores)
  paired.md                        ablation and sampling: paired differences against the baseline setting
                                   on the same seeds (ddfbench.report.paired)
A report comes from one code commit: records from several commits are refused (exit 2) unless
--allow-mixed-commits, which names the commits at the top of report.md.
`--status [OVERRIDE ...]` prints which runs of the sweep are done, failed or missing instead
(ddfbench.report.status).
`--claims RESULTS [--out RESULTS/claims.md] [--carry reports/claims.md]` writes the paper-claims table
from the records of every experiment below RESULTS (ddfbench.report.claims), beside them unless --out says
otherwise (the committed reports/claims.md comes from the committed records: regenerate --from-records); --carry
keeps the previous table's rows for the claims whose experiments have no records there (marked †).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
from collections import Counter
from typing import Any

import pandas as pd

from ddfbench.core.errors import InputError, one_line
from ddfbench.report import compact, convergence, finalists, shape_suite
from ddfbench.report.gallery import CAPTION, GALLERY, write_gallery
from ddfbench.report.paired import paired_report
from ddfbench.report.plots import PLOTS, plots_for, write_plots
from ddfbench.report.records import distinct_shape_names, family_class
from ddfbench.report.tables import per_run, summarize, to_csv, to_latex, to_markdown
from ddfbench.run.runs import code_commits

OPTIONS_FILE = "report_options.json"
STATUS_FILE = "sweep_status.md"


def _experiment(records: list[dict[str, Any]], source: str) -> str:
    names = Counter(str(r.get("experiment")) for r in records)
    return names.most_common(1)[0][0] if names else os.path.basename(os.path.normpath(source))


def _experiment_file(records: list[dict[str, Any]], experiment: str) -> str:
    """The conf/experiment file the runs were launched with (their `+experiment=NAME` override), which picks
    the report's plots and sections: a sweep renamed by experiment_name (gan_epochs_b256) keeps its file's
    sections. The experiment's name where no run names a file."""
    from ddfbench.run.overrides import values_of  # imports Hydra's override parser: only when asked

    files = Counter(name for r in records for name in values_of(r.get("overrides") or [], "experiment"))
    return files.most_common(1)[0][0] if files else experiment


def _sweep_lines(records_dir: str, sweep: list[str] | None, records: list[dict[str, Any]]) -> list[str]:
    """The sweep's status (done / failed / missing), or one line saying why it is unknown.
    sweep: the sweep's overrides (default: the newest sweep of this experiment, see status.py); records: those
    read from records_dir."""
    try:
        from ddfbench.report import status
    except ImportError:
        return []
    try:
        st = status.sweep_status(records_dir, sweep, records)
    except Exception as exc:  # the status is an extra: a report is still written without it
        return [f"Sweep status unknown ({type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc) else ''})."]
    return ["```", status.format_status(records_dir, st), "```"]


class MixedCommits(ValueError):
    """Records of one report come from more than one code commit."""


def by_commit(records: list[dict[str, Any]]) -> str:
    """Each code commit of the records with its record count and one run folder (key), fewest first."""
    groups: dict[str, list[dict[str, Any]]] = {}
    for rec in records:
        groups.setdefault(code_commits([rec])[0], []).append(rec)
    return "; ".join(f"{sha}: {len(recs)} record{'s' * (len(recs) > 1)}, e.g. {recs[0].get('_dir') or recs[0]['key']}"
                     for sha, recs in sorted(groups.items(), key=lambda item: (len(item[1]), item[0])))


SOURCE_OF_KIND = {
    None: "the exact mesh (no training samples)",
    "rays": "ray samples: exact hit distances and hit / line-hit labels from the sampler",
    "sdf": "SDF samples: exact signed distances at points",
}


def information_lines(records: list[dict[str, Any]]) -> list[str]:
    """Markdown lines saying what each model in the records was built or trained from (its family's
    sample_kind), so that a row built from the exact mesh is not read as a learned result."""
    by_source: dict[str, set[str]] = {}
    for rec in records:
        family = family_class(str(rec.get("family")))
        if family is None:  # a family this checkout does not have
            continue
        kind = family.sample_kind
        by_source.setdefault(SOURCE_OF_KIND.get(kind, str(kind)), set()).add(str(rec.get("model")))
    if not by_source:
        return []
    return ["What each model had to build from:", ""] + [f"- {', '.join(sorted(models))}: {source}"
                                                       for source, models in sorted(by_source.items())]


def scene_lines(records: list[dict[str, Any]]) -> list[str]:
    """Markdown lines naming the scenes the image columns (mask IoU, depth MAE, normal error, render times) come from:
    outputs, size, cameras and the timing of each distinct scene of the records; [] where none rendered."""
    scenes: dict[str, int] = {}
    for rec in records:
        scene = (rec.get("config") or {}).get("scene") or {}
        if not scene.get("outputs"):
            continue
        timing, orbit = scene.get("timing") or {}, scene.get("cameras") or {}
        cameras = len(orbit["positions"]) if orbit.get("positions") else orbit.get("n")  # scene.py: positions win
        text = (f"`{scene.get('name')}`: {', '.join(scene['outputs'])} at {scene.get('width')}×{scene.get('height')}, "
                f"{cameras} camera{'s' * (cameras != 1)}, against the oracle's render of the exact mesh; warm time the "
                f"median of up to {timing.get('repeats')} renders after {timing.get('warmup')} warm-up")
        scenes[text] = scenes.get(text, 0) + 1
    if not scenes:
        return []
    return ["", "The image columns come from the scene" + ("s" if len(scenes) > 1 else "") + ":", ""] + \
        [f"- {text} ({n} run{'s' * (n > 1)})" for text, n in sorted(scenes.items())]


def _write_section(out_dir: str, name: str, title: str, rows: list[dict[str, Any]], markdown: str) -> str:
    """Write <name>.md (the titled markdown table) and <name>.csv (its rows) into out_dir; return the markdown."""
    text = f"## {title}\n\n" + markdown
    with open(os.path.join(out_dir, f"{name}.md"), "w") as fh:
        fh.write(text)
    pd.DataFrame(rows).to_csv(os.path.join(out_dir, f"{name}.csv"), index=False)
    return text


def write_report(source: str, out_dir: str, note: str | None = None,
                 kinds: tuple[str, ...] | None = None, sweep: list[str] | None = None,
                 allow_mixed_commits: bool = False, draw: bool = True) -> str:
    """Write the tables, plots, report.md and the compact records for the records of source (a folder of run
    records or a compact file); return the markdown table. Every file but the images and sweep_status.md
    depends on the records and options alone, so the report regenerates byte for byte from its compact file.
    draw=False draws no image and links the ones out_dir already holds (a check of the text files).
    Raises MixedCommits when the records come from several code commits (unless allowed)."""
    raw = compact.load_records(source, strict=True)
    records = distinct_shape_names(raw)  # the tables' names; the compact file keeps the records as they are
    if not records:
        inside = os.path.join(source, compact.FILE)
        hint = f" (a compact file is read by its path: {inside})" if os.path.isfile(inside) else ""
        raise InputError(f"{source}: no run records{hint}: nothing written")
    shas = code_commits(records)
    if len(shas) > 1 and not allow_mixed_commits:
        raise MixedCommits(f"{source}: records from {len(shas)} code commits ({by_commit(records)}); rerun the "
                           "odd ones with force=true on one commit, or pass --allow-mixed-commits")
    experiment = _experiment(records, source)
    kind = _experiment_file(records, experiment)
    # the tuning protocol's table holds the seeds its candidates are scored on; its confirmation's runs have a section
    df = summarize(finalists.selection_records(records) if kind == "tune_finalists" else records)
    os.makedirs(out_dir, exist_ok=True)
    if os.path.abspath(source) != os.path.abspath(os.path.join(out_dir, compact.FILE)):
        compact.write_compact(raw, os.path.join(out_dir, compact.FILE))
    with open(os.path.join(out_dir, OPTIONS_FILE), "w") as fh:
        json.dump({"note": note, "plots": list(kinds) if kinds is not None else None,
                   "allow_mixed_commits": allow_mixed_commits}, fh, indent=1)
        fh.write("\n")
    if os.path.isdir(source):  # the machine's paths are written as <out_dir>, the folder above the records
        text = "\n".join(["# Sweep status when the report was written", "", *_sweep_lines(source, sweep, records)])
        text += "\n"
        with open(os.path.join(out_dir, STATUS_FILE), "w") as fh:
            fh.write(text.replace(os.path.dirname(os.path.abspath(source)), "<out_dir>"))
    md = to_markdown(df)
    with open(os.path.join(out_dir, "table.md"), "w") as fh:
        fh.write(md)
    with open(os.path.join(out_dir, "table.tex"), "w") as fh:
        fh.write(to_latex(df))
    to_csv(df, os.path.join(out_dir, "table.csv"))
    per_run(records).to_csv(os.path.join(out_dir, "runs.csv"), index=False)
    chosen = kinds if kinds is not None else plots_for(kind)
    written = write_plots(records, out_dir, chosen) if draw else \
        [p for k in chosen for p in (os.path.join(out_dir, f"{k}.{ext}") for ext in ("png", "pdf")) if os.path.isfile(p)]
    gallery = write_gallery(records, out_dir) or os.path.join(out_dir, GALLERY)
    written += [gallery] if os.path.isfile(gallery) else []  # a compact rebuild keeps the gallery it cannot draw
    pairs = paired_report(kind, records)
    if pairs is not None:
        with open(os.path.join(out_dir, "paired.md"), "w") as fh:
            fh.write(pairs)
    extra = [pairs] if pairs is not None else []
    if kind == "shape_suite":
        extra += shape_suite.sections(records, out_dir, draw)
    if kind == "tune_finalists":
        extra += finalists.sections(records)
    if kind in ("convergence", "paper_ddf", "gan_epochs"):
        rows = convergence.time_to_floor_rows(records)
        extra.append(_write_section(out_dir, "time_to_floor", "Time to reach the noise floor", rows,
                                    convergence.to_markdown(rows)))
        rows = convergence.stability_rows(records)
        extra.append(_write_section(out_dir, "stability", "Stability: how many runs diverged", rows,
                                    convergence.stability_markdown(rows)))
        rows = convergence.probe_rows(records)
        extra.append(_write_section(out_dir, "probes", "Every probe of every run", rows,
                                    convergence.probe_markdown(rows)))
    lines = [f"# {experiment}", ""]
    if note:
        lines += [f"**{note}**", ""]
    if len(shas) > 1:
        lines += [f"**Mixed code commits: {', '.join(shas)}: rows may not be comparable.**", ""]
    lines += [f"{len(records)} run records (code: {', '.join(shas) or 'unknown'}), kept in `{compact.FILE}` beside "
              f"this report.", ""]
    lines += ["", md, "", *information_lines(records), *scene_lines(records)]
    for part in extra:
        lines += ["", part]
    for p in (p for p in written if p.endswith(".png")):
        lines += [f"![{os.path.basename(p)}]({os.path.basename(p)})"] + ([CAPTION, ""] if p == gallery else [])
    lines += ["", "Record keys (config hashes) per row:", ""]
    if not df.empty:
        lines += [f"- {row['model']} {row['shape']}: {row['keys']}" for _, row in df.iterrows()]
    with open(os.path.join(out_dir, "report.md"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
    return md


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ddfbench.report", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("records", nargs="?", help="folder of run records (results/ablation) or a compact file "
                                                     f"(reports/ablation/{compact.FILE})")
    parser.add_argument("--out", help="report folder (default: beside the records: <folder>/report, or the compact "
                                      "file's folder)")
    parser.add_argument("--note", help="a line written at the top of report.md (e.g. 'reduced budget: ...')")
    parser.add_argument("--plots", help=f"comma-separated plot kinds ({', '.join(PLOTS)}; 'none' for no plot); "
                                        "default: by the runs' experiment file (+experiment=NAME), else its name")
    parser.add_argument("--sweep", nargs="+", metavar="OVERRIDE",
                        help="the sweep's overrides for the status in report.md (default: its newest sweep)")
    parser.add_argument("--allow-mixed-commits", action="store_true",
                        help="report records from several code commits (named at the top of report.md)")
    parser.add_argument("--claims", action="store_true",
                        help="write the paper-claims table from every experiment below the records folder "
                             "(to RECORDS/claims.md unless --out)")
    parser.add_argument("--carry", metavar="CLAIMS_MD",
                        help="with --claims: keep this previous claims.md's rows for claims without records")
    parser.add_argument("--status", nargs="*", metavar="OVERRIDE",
                        help="print done / failed / missing runs of the sweep instead of writing a report")
    args = parser.parse_args(argv)
    if args.records is None and args.status and "=" not in args.status[0]:
        args.records = args.status.pop(0)  # `--status results/<experiment>`: the folder came after the flag
    if args.records is None:
        parser.error("the folder of run records is required, e.g. results/ablation")
    if args.carry and not args.claims:
        parser.error("--carry goes with --claims")
    if not args.claims:  # a report and a sweep's status compose the experiment's configs
        from ddfbench.run.checks import check_conf_found  # (it imports the families: torch)

        try:
            check_conf_found()
        except InputError as exc:
            print(f"ddfbench.report: {exc}", file=sys.stderr)
            return 2
    if args.status is not None:
        from ddfbench.report import status

        return status.main(args.records, args.status)
    is_compact = args.records.endswith(".jsonl.gz") and os.path.isfile(args.records)
    if not (os.path.isdir(args.records) or is_compact):
        print(f"ddfbench.report: {args.records}: no such folder of run records or compact file", file=sys.stderr)
        return 2
    if args.claims:
        from ddfbench.report.claims import write_claims

        out = args.out or os.path.join(args.records, "claims.md")
        try:
            print(write_claims(args.records, out, args.carry))
        except InputError as exc:
            print(f"ddfbench.report: {exc}", file=sys.stderr)
            return 2
        print(f"wrote {out}")
        return 0
    kinds = None
    if args.plots:
        kinds = tuple(k for k in args.plots.split(",") if k and k != "none")
        unknown = [k for k in kinds if k not in PLOTS]
        if unknown:
            print(f"ddfbench.report: --plots {','.join(unknown)}: unknown kind (valid: {', '.join(PLOTS)})",
                  file=sys.stderr)
            return 2
    out = args.out or (os.path.dirname(os.path.abspath(args.records)) if is_compact else os.path.join(args.records, "report"))
    from ddfbench.run.checks import writable_folder

    made = not os.path.exists(out)
    try:
        writable_folder(out, "--out ")
        print(write_report_whole(args.records, out, note=args.note, kinds=kinds, sweep=args.sweep,
                                 allow_mixed_commits=args.allow_mixed_commits))
    except Exception as exc:  # a bad input, or a run's artifact that cannot be drawn: one line, nothing written
        if made and os.path.isdir(out) and not os.listdir(out):  # no empty folder left either
            os.rmdir(out)
        message = str(exc) if isinstance(exc, (MixedCommits, InputError)) else one_line(exc)
        print(f"ddfbench.report: {message}" + ("" if message.endswith("nothing written") else ": nothing written"),
              file=sys.stderr)
        return 2
    print(f"wrote {out}/report.md, table.md, table.csv, runs.csv, table.tex and plots")
    return 0


def write_report_whole(source: str, out_dir: str, **options: Any) -> str:
    """write_report into a scratch folder beside out_dir (holding out_dir's files, which it may link), then every file
    it wrote into out_dir: a report that fails midway (an artifact that cannot be read) leaves out_dir as it was. The
    compact file a report is rebuilt from is not written over."""
    scratch = tempfile.mkdtemp(prefix=".report-", dir=os.path.dirname(os.path.abspath(out_dir)))
    try:
        for name in os.listdir(out_dir):
            if os.path.isfile(os.path.join(out_dir, name)):
                shutil.copy2(os.path.join(out_dir, name), scratch)
        md = write_report(source, scratch, **options)
        if os.path.abspath(source) == os.path.abspath(os.path.join(out_dir, compact.FILE)):
            os.remove(os.path.join(scratch, compact.FILE))
        for name in os.listdir(scratch):
            os.replace(os.path.join(scratch, name), os.path.join(out_dir, name))
        return md
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
