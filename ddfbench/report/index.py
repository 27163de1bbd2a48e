"""reports/index.md: every committed report folder at a glance — which suite tier it belongs to, how many runs, from
which code commit, and whether it regenerates from committed files (`regenerate --from-records`): a report from its
records, a re-measurement from its measured rows, a tuning study from its trial table.

A report folder is a folder below reports/ with a report.md, a table.csv, a tuning study's trials.md, or compact
records. Its runs and commits are read from its records when it has them, else from the first such line its tool
wrote ("N run records ... (code: SHA)", a study's "N records ... (code SHA", a re-measurement's "N runs ... records of
code SHA[, SHA]", or an older one's "N runs measured again" with no commit). A re-measurement
(ddfbench.report.reevaluate, zero_level, edge_error) reads the runs' artifacts (meshes, networks, renders), which no
compact record holds; its tables regenerate from the measured rows it saved beside them (ddfbench.report.measured),
and one written before those were saved only where its runs are. A tuning study (ddfbench.report.tune) regenerates
from its trials.csv and study.json. `regenerate --from-records` writes the index and
`--check` compares it, so a report that gains or loses its records shows here.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

from ddfbench.report import compact, measured
from ddfbench.report import tune as tune_report
from ddfbench.report.suite import ROOT, load_suite
from ddfbench.report.tables import pipe_lines
from ddfbench.run.runs import code_commits

FILE = "index.md"
MARKERS = ("report.md", "table.csv", "trials.md", compact.FILE)
TEXTS = ("report.md", "best.md", "trials.md", "table.md")  # where a tool wrote its first line, in this order
REMEASURED = re.compile(r"^`python -m ddfbench\.report\.(reevaluate|zero_level|edge_error)\b")
_SHAS = r"([0-9a-f]{7,40}(?:, [0-9a-f]{7,40})*)"
_RECORDS = re.compile(r"(\d+) (?:run )?records\b[^(\n]*\(code:? " + _SHAS)
_RUNS = re.compile(r"(\d+) (?:[A-Za-z]+ )?runs?\b[^\n]*?(?:records of code " + _SHAS + "|$)", re.M)
REGENERATES = "yes"
FROM_ROWS = "yes: from its measured rows"
FROM_TRIALS = "yes: from its trial table"
REGENERABLE = (REGENERATES, FROM_ROWS, FROM_TRIALS)
NOT_COMMITTED = "no: records not committed"
ARTIFACTS = "no: re-measured from the runs' artifacts"


@dataclass
class Provenance:
    """What one report folder was made from: runs (None when unknown), code commits (7-character SHAs) and whether
    it regenerates from committed records (REGENERATES), from its measured rows (FROM_ROWS), from its trial table
    (FROM_TRIALS) or why not."""

    runs: int | None
    commits: list[str]
    regenerates: str


def report_folders(reports: str) -> list[str]:
    """Every report folder below `reports` (any depth), relative to it, sorted."""
    return sorted(os.path.relpath(folder, reports) for folder, _, files in compact.walk_visible(reports)
                  if folder != reports and any(m in files for m in MARKERS))


def provenance(folder: str) -> Provenance:
    """The provenance of one report folder, from its records or the first line its tool wrote."""
    if os.path.isfile(os.path.join(folder, compact.FILE)):
        records = compact.read_compact(os.path.join(folder, compact.FILE))
        return Provenance(len(records), sorted({sha[:7] for sha in code_commits(records)}), REGENERATES)
    remeasured, study = measured.holds_rows(folder), tune_report.holds_study(folder)
    for name in TEXTS:
        path = os.path.join(folder, name)
        if not os.path.isfile(path):
            continue
        with open(path, encoding="utf-8") as fh:
            text = fh.read()
        status = (FROM_TRIALS if study else FROM_ROWS if remeasured else ARTIFACTS if REMEASURED.match(text)
                  else NOT_COMMITTED)
        found = _RECORDS.search(text) or _RUNS.search(text)
        if found or status in (ARTIFACTS, FROM_ROWS, FROM_TRIALS):
            shas = found.group(2) if found and found.group(2) else ""
            return Provenance(int(found.group(1)) if found else None,
                              sorted({s[:7] for s in shas.split(", ") if s}), status)
    return Provenance(None, [], NOT_COMMITTED)


def tiers_of(suite: str, reports: str) -> dict[str, str]:
    """{report folder relative to `reports`: its tier in the suite}, for the suite's report folders below it."""
    out = {}
    for tier, entries in load_suite(suite).items():
        for entry in entries:
            rel = os.path.relpath(os.path.join(ROOT, entry.report), os.path.abspath(reports))
            if not rel.startswith(os.pardir):
                out[rel] = tier
    return out


def not_regenerating(remeasured: int, lost: int) -> str:
    """The index's sentence on the folders that do not regenerate, by kind; empty when every folder does."""
    kinds = []
    if remeasured:
        kinds.append(f"{remeasured} re-measurement{'s' if remeasured != 1 else ''} saved no rows, and the artifacts "
                     "stay with the runs")
    if lost:
        kinds.append(f"{lost} report{'s' if lost != 1 else ''} of runs whose records stayed on the machine that ran "
                     "them, so their tables cannot be recomputed from this repository")
    return f" Not regenerating: {'; '.join(kinds)}." if kinds else ""


def render_index(reports: str, suite: str = "v1") -> str:
    """The index as Markdown: one row per report folder, the suite's reports first (by tier, as the suite file
    lists them), then the others by name."""
    tiers = tiers_of(suite, reports)
    order = {name: i for i, name in enumerate(tiers)}
    folders = sorted(report_folders(reports), key=lambda f: (order.get(f, len(order)), f))
    found = {name: provenance(os.path.join(reports, name)) for name in folders}
    rows = [[f"[`{name}/`]({name}/)", f"{suite} {tiers[name]}" if name in tiers else "–",
             f"{p.runs if p.runs is not None else '–'}", ", ".join(p.commits) or "–", f"{p.regenerates}"]
            for name, p in found.items()]
    done = sum(p.regenerates == REGENERATES for p in found.values())
    from_rows = sum(p.regenerates == FROM_ROWS for p in found.values())
    from_trials = sum(p.regenerates == FROM_TRIALS for p in found.values())
    remeasured = sum(p.regenerates == ARTIFACTS for p in found.values())
    lost = len(rows) - done - from_rows - from_trials - remeasured
    return "\n".join([
        "# Reports at a glance",
        "",
        f"Generated by `python -m ddfbench.report.regenerate --from-records` (ddfbench.report.index). "
        f"{done + from_rows + from_trials} of {len(rows)} report folders regenerate from committed files: {done} "
        f"reports from their records (`records.jsonl.gz`), {from_rows} re-measurements of runs' artifacts (meshes, "
        f"networks, renders) from the rows they measured (`measured.jsonl.gz`), {from_trials} tuning studies from "
        f"their trial tables (`trials.csv`, `study.json`).{not_regenerating(remeasured, lost)} "
        f"Suite {suite}'s tiers: `conf/suite/{suite}.yaml` (`python -m ddfbench.suite status "
        f"{suite}` says which are stale). Timing benches (`bench/`) keep their raw JSON beside each table.",
        "",
        *pipe_lines(["report", "suite tier", "runs", "code", "regenerates from records"], rows),
        "",
    ])


def write_index(reports: str, path: str, suite: str = "v1") -> str:
    """Write the index of `reports` to path; return path. A report whose records cannot be read raises InputError
    before the file is opened: the index there stays as it was."""
    text = render_index(reports, suite)
    with open(path, "w", encoding="utf-8") as fh:
        fh.write(text)
    return path
