"""`python -m ddfbench.suite run NAME --tier TIER [--only EXP,...] [--dry-run] [--from-reports] [--results DIR]
[-- OVERRIDE ...]` and `python -m ddfbench.suite status NAME`.

A suite file (conf/suite/<name>.yaml) names the benchmark: per tier, each experiment with the report folder it writes
and the overrides its command line adds. `run --dry-run` prints each experiment's jobs per model and its estimated
CPU-hours, from the committed records' wall time per job (the report's own records.jsonl.gz at the job's capacity level,
else of its model, else any committed record of the same model, else unknown; a wall-clock job costs at least its bound;
a fixed-work job's fit time is scaled to its own steps or epochs); `run` runs each experiment (Hydra resumes finished
jobs and prints a progress line per job with an ETA), then the sweeps its report asks for (FOLLOW_UPS: the tuning
protocol's confirmation on fresh seeds, from the records), then writes its report (over the committed one only when no
job failed); with --from-reports it first restores the reports' committed records into the results folder, so that a
tier resumes across machines. `status` says, per report, the code commit its records come from and whether the code or
config of a model it ran changed since (stale), by `git diff` (the modules that write nothing into a record,
RESULT_NEUTRAL, left out, and a file whose every change since is a commit the suite file lists as `result_neutral`).
Every suite command needs a git checkout: it reads and writes the checkout's committed reports/.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import re
import shlex
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from typing import Any

from omegaconf import OmegaConf

from ddfbench.core import plugins
from ddfbench.core.errors import InputError, first_line
from ddfbench.core.plugins import CONF_DIR
from ddfbench.report import compact, finalists
from ddfbench.report.status import compose_job, sweep_jobs
from ddfbench.run import runs
from ddfbench.run.checks import check_conf_found, writable_folder

ROOT = os.path.dirname(os.path.realpath(CONF_DIR))  # the checkout (an installed wheel: its package folder)
# experiment: its records -> the overrides of each sweep its report still needs (run into the same out_dir)
FOLLOW_UPS = {"tune_finalists": finalists.confirmation_sweeps}


@dataclass
class Entry:
    """One experiment of a tier: its report folder (relative to the repository) and extra overrides."""

    experiment: str
    report: str
    overrides: list[str] = field(default_factory=list)


SUITE_KEYS = ("version", "tiers", "result_neutral")  # a suite file's keys
ENTRY_KEYS = ("report", "overrides")  # an experiment's keys in a tier


def _suite_file(name: str) -> dict[str, Any]:
    """conf/suite/<name>.yaml as a plain dict; a one-line InputError naming the suites there is none, or naming the
    file when it is not YAML, not a mapping or holds a key a suite file does not have."""
    path = os.path.join(CONF_DIR, "suite", f"{name}.yaml")
    if not os.path.isfile(path):
        known = sorted(f[:-5] for f in os.listdir(os.path.join(CONF_DIR, "suite")) if f.endswith(".yaml"))
        raise InputError(f"suite '{name}': no conf/suite/{name}.yaml (suites: {', '.join(known)})")
    try:
        found = OmegaConf.to_container(OmegaConf.load(path))
    except Exception as exc:  # yaml's parse errors, OmegaConf's, an unreadable file
        mark = getattr(exc, "problem_mark", None)
        what = f"{getattr(exc, 'problem', None) or first_line(exc)}{f' at line {mark.line + 1}' if mark else ''}"
        raise InputError(f"conf/suite/{name}.yaml: not a readable YAML file ({what})") from None
    if found is None:
        return {}
    if not isinstance(found, dict):
        raise InputError(f"conf/suite/{name}.yaml: needs a mapping of {', '.join(SUITE_KEYS)}, not a "
                         f"{type(found).__name__}")
    if unknown := [str(k) for k in found if k not in SUITE_KEYS]:
        raise InputError(f"conf/suite/{name}.yaml: unknown key {', '.join(unknown)} (known: {', '.join(SUITE_KEYS)})")
    return found


def load_suite(name: str) -> dict[str, list[Entry]]:
    """{tier: entries} of conf/suite/<name>.yaml; a one-line InputError naming the file and key when malformed (a
    tier that is not a mapping, an experiment's key other than report and overrides, overrides that are not a list
    of strings: a misspelt `overrides` would run the experiment without them)."""
    where = f"conf/suite/{name}.yaml"
    tiers = _suite_file(name).get("tiers")
    if not isinstance(tiers, dict) or not tiers:
        raise InputError(f"{where}: needs `tiers: {{tier: {{experiment: {{report: ...}}}}}}`")
    out: dict[str, list[Entry]] = {}
    for tier, entries in tiers.items():
        out[tier] = []
        if not isinstance(entries, dict | None):
            raise InputError(f"{where}: tiers.{tier}: needs {{experiment: {{report: ...}}}}, not a "
                             f"{type(entries).__name__}")
        for experiment, spec in (entries or {}).items():
            if not os.path.isfile(os.path.join(CONF_DIR, "experiment", f"{experiment}.yaml")):
                raise InputError(f"{where}: tiers.{tier}.{experiment}: no conf/experiment/{experiment}.yaml")
            if not isinstance(spec, dict) or not spec.get("report"):
                raise InputError(f"{where}: tiers.{tier}.{experiment}: needs a `report` folder")
            if unknown := [str(k) for k in spec if k not in ENTRY_KEYS]:
                raise InputError(f"{where}: tiers.{tier}.{experiment}: unknown key {', '.join(unknown)} (known: "
                                 f"{', '.join(ENTRY_KEYS)})")
            overrides = spec.get("overrides") or []
            if not isinstance(overrides, list) or not all(isinstance(o, str) for o in overrides):
                raise InputError(f"{where}: tiers.{tier}.{experiment}.overrides: needs a list of overrides (strings), "
                                 f"not {overrides!r}")
            out[tier].append(Entry(experiment, str(spec["report"]), list(overrides)))
    return out


@dataclass(frozen=True)
class Job:
    """What a job's cost depends on: its model, capacity level ("" when the sweep sets none) and fit budget as its
    composed config gives it (train.budget; train.max_seconds, the wall-clock bound; work: train.max_steps or
    train.max_epochs of a steps or epochs budget, 0 when unknown)."""

    model: str
    level: str
    budget: str
    max_seconds: float
    work: float = 0.0


@dataclass
class Sweep:
    """An experiment's sweep as Hydra's basic sweeper expands it (one job composed per model, level and train
    overrides): how many jobs of each kind."""

    jobs: dict[Job, int]

    def per_model(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for job, n in self.jobs.items():
            out[job.model] = out.get(job.model, 0) + n
        return out


def expand(entry: Entry) -> Sweep:
    """The entry's sweep: its jobs per model and level, and its fit budget."""
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra
    from hydra.types import RunMode

    GlobalHydra.instance().clear()
    with initialize_config_dir(CONF_DIR, version_base="1.3", job_name="ddfbench_suite"):
        loader = GlobalHydra.instance().config_loader()
        overrides = [f"+experiment={entry.experiment}", *entry.overrides]
        master = loader.load_configuration("config", overrides, run_mode=RunMode.MULTIRUN)
        jobs: dict[Job, int] = {}
        budgets: dict[tuple[str, ...], tuple[str, str, str, float, float]] = {}
        for job_overrides in sweep_jobs(loader, master, overrides)[1]:
            what = tuple(o for o in job_overrides if _sets_budget(o.split("=", 1)[0].lstrip("+")))
            if what not in budgets:  # compose one job per model, level and train overrides
                budgets[what] = _budget(*compose_job(loader, master, job_overrides), job_overrides)
            job = Job(*budgets[what])
            jobs[job] = jobs.get(job, 0) + 1
        return Sweep(jobs)


def _sets_budget(key: str) -> bool:
    """Whether an override of key can change a job's fit budget: the model, its level, a train key (no sampler level
    or scene sets one; a level is a partial config of the job, plugins.job_config)."""
    return key in ("model", "capacity") or key.startswith("train.")


def _budget(job: dict[str, Any], choices: dict[str, str], overrides: list[str]) -> tuple[str, str, str, float, float]:
    """(model, level, budget, max_seconds, work) of one job's config with its level applied (status.compose_job: a
    level may set train.max_steps) and its overrides."""
    train = job.get("train") or {}
    budget = str(train.get("budget", "steps"))
    work = {"steps": train.get("max_steps"), "epochs": train.get("max_epochs")}.get(budget)
    return (str(choices.get("model", "?")), _capacity(overrides), budget, float(train.get("max_seconds") or 0.0),
            float(work or 0.0))


def _seconds(rec: dict[str, Any]) -> float | None:
    try:
        return (dt.datetime.fromisoformat(rec["finished"]) - dt.datetime.fromisoformat(rec["started"])).total_seconds()
    except (KeyError, TypeError, ValueError):
        return None


def _capacity(overrides: list[str]) -> str:
    """The capacity level a command line sets ("" when none)."""
    from ddfbench.run.overrides import values_of  # imports Hydra's override parser: only when asked

    return next(iter(values_of(overrides, "capacity")), "")


def _level(rec: dict[str, Any]) -> str:
    """The capacity level a record's command line set ("" when none)."""
    return _capacity(rec.get("overrides") or [])


def committed_records(reports: str) -> dict[str, list[dict[str, Any]]]:
    """{report folder relative to the repository: its compact records} for every records.jsonl.gz below reports."""
    return {os.path.relpath(folder, ROOT): compact.read_compact(os.path.join(folder, compact.FILE))
            for folder in compact.folders_holding(reports, compact.FILE)}


def _outside_fit(rec: dict[str, Any]) -> float:
    """Wall seconds a record spent outside its fit (sampling, extraction, metrics, renders). Its started..finished
    span is its last process's: a fit resumed from a checkpoint counts more fit seconds than that span holds."""
    return max(0.0, (_seconds(rec) or 0.0) - float((rec.get("fit") or {}).get("seconds") or 0.0))


def _scaled_seconds(rec: dict[str, Any], job: Job) -> float:
    """A record's seconds for the job's fixed work: its fit time (all of it, a resumed fit's too) scaled by the
    job's steps or epochs over the record's own (a 40-epoch job from a 0.06-epoch record), plus what it spent outside
    the fit; unscaled where either side's work is unknown."""
    fit = rec.get("fit") or {}
    done = {"steps": fit.get("steps"), "epochs": fit.get("epochs")}.get(job.budget)
    fit_seconds = float(fit.get("seconds") or 0.0)
    scale = job.work / float(done) if job.work > 0 and done and fit_seconds else 1.0
    return _outside_fit(rec) + fit_seconds * scale


def job_seconds(entry: Entry, job: Job, records: dict[str, list[dict[str, Any]]]) -> tuple[float | None, str]:
    """Wall seconds of one job and where they were measured: the median of the first non-empty of (the entry's
    report, same model and level), (the entry's report, same model), (any report of the same experiment, model and
    level), (any report, same model). A level's meaning is its experiment's, so another experiment's records count
    only by model. A fixed-work job's fit time is scaled to its steps or epochs; a wall-clock job costs at least its
    bound plus what the measured jobs spent outside their fit (evaluation, rendering, accuracy probes: a lower bound
    where they took fewer probes)."""
    model, level = job.model, job.level
    candidates = (
        (entry.report, lambda folder, r: folder == entry.report and r.get("model") == model and _level(r) == level),
        (entry.report, lambda folder, r: folder == entry.report and r.get("model") == model),
        ("other reports", lambda folder, r: (r.get("experiment") == entry.experiment and r.get("model") == model
                                             and _level(r) == level)),
        ("other reports", lambda folder, r: r.get("model") == model),
    )
    for source, matches in candidates:
        found = [r for folder, recs in records.items() for r in recs if matches(folder, r) and _seconds(r) is not None]
        if found:
            seconds = statistics.median(_scaled_seconds(r, job) for r in found)
            if job.budget == "wall-clock":
                outside = statistics.median(_outside_fit(r) for r in found)
                seconds = max(seconds, job.max_seconds + outside)
            return seconds, source
    return None, "no record"


def tier_entries(suite: str, tier: str, only: list[str] | None = None) -> list[Entry]:
    """The tier's experiments, or those of them named in only (an unknown tier or name: InputError naming it)."""
    tiers = load_suite(suite)
    if tier not in tiers:
        raise InputError(f"suite {suite}: no tier '{tier}' (tiers: {', '.join(tiers)})")
    names = [e.experiment for e in tiers[tier]]
    unknown = [n for n in only or [] if n not in names]
    if unknown:
        raise InputError(f"suite {suite}, tier {tier}: no experiment {', '.join(unknown)} (it has {', '.join(names)})")
    return [e for e in tiers[tier] if not only or e.experiment in only]


def plan(suite: str, tier: str, reports: str = os.path.join(ROOT, "reports"),
         only: list[str] | None = None, extra: list[str] | None = None) -> list[dict[str, Any]]:
    """Per experiment of the tier (or of only), its sweep with the suite's overrides and then `extra` (those `run`
    adds to every command line): jobs, estimated CPU-hours (None when a model has no measured record), sources."""
    records = committed_records(reports)
    rows = []
    for entry in tier_entries(suite, tier, only):
        sweep = expand(Entry(entry.experiment, entry.report, [*entry.overrides, *(extra or [])]))
        hours, unknown, sources = 0.0, set(), set()
        for job, n in sweep.jobs.items():
            seconds, source = job_seconds(entry, job, records)
            if seconds is None:
                unknown.add(job.model)
            else:
                hours += n * seconds / 3600
                sources.add(source)
        rows.append({"experiment": entry.experiment, "report": entry.report, "jobs": sum(sweep.jobs.values()),
                     "models": len(sweep.per_model()), "cpu_hours": hours, "unknown": sorted(unknown),
                     "sources": sorted(sources), "overrides": entry.overrides})
    return rows


def print_plan(rows: list[dict[str, Any]]) -> None:
    for r in rows:
        unknown = f" + {len(r['unknown'])} model(s) never measured ({', '.join(r['unknown'])})" if r["unknown"] else ""
        print(f"{r['experiment']:<16} {r['jobs']:>5} jobs  {r['cpu_hours']:6.2f} CPU-h{unknown}  -> {r['report']}"
              f"  (cost from {', '.join(r['sources']) or 'nothing'})")
        if r["experiment"] in FOLLOW_UPS:
            print(f"{'':<16} + the sweeps its report asks for once it has run (not counted)")
    total = sum(r["cpu_hours"] for r in rows)
    print(f"{'total':<16} {sum(r['jobs'] for r in rows):>5} jobs  {total:6.2f} CPU-h (wall per job as recorded, "
          "one job at a time; more with unmeasured models)")


def run(suite: str, tier: str, results: str, extra: list[str] | None = None, from_reports: bool = False,
        only: list[str] | None = None) -> int:
    """Run every experiment of the tier into results/ (resuming) with the suite's overrides and then `extra` (e.g. a
    launcher, threads), then the sweeps its records ask for (FOLLOW_UPS), then write its report (write_report: into
    the committed folder only when none of them had a failed job); the worst exit code. from_reports: first restore
    each report's committed records into results/ (compact.restore), so that a tier cut short on another machine goes
    on where its committed records end (the report refuses records of two code commits: run it from the records'
    commit). only: the tier's experiments to run (default: all)."""
    entries = tier_entries(suite, tier, only)
    writable_folder(results, "--results ")
    committed = {e.report: os.path.join(ROOT, e.report) for e in entries}
    if from_reports:
        here = runs.code_sha()
        for report, folder in committed.items():
            shas = runs.code_commits(compact.records_of(folder))
            if shas and shas != [here]:
                raise InputError(f"--from-reports: {report}'s records are of code {', '.join(s[:7] for s in shas)}, "
                                 f"this checkout's code is {str(here)[:7]}: run from a worktree at their commit (a "
                                 "report refuses records of two commits)")
    rc = 0
    for entry in entries:
        if from_reports and os.path.isfile(os.path.join(committed[entry.report], compact.FILE)):
            written, kept, left = compact.restore(os.path.join(committed[entry.report], compact.FILE), results)
            print(f"{entry.experiment}: restored {written} committed records from {entry.report} ({kept} already "
                  f"in results, {left} left out to run again)", flush=True)
        cmd = [sys.executable, "-m", "ddfbench", f"+experiment={entry.experiment}", f"out_dir={results}", "quiet=true",
               *entry.overrides, *(extra or [])]
        print("$", shell_line(cmd), flush=True)
        started = time.time()
        swept = subprocess.run(cmd).returncode
        swept = swept if swept >= 0 else 1  # a sweep killed by a signal has a negative code
        rc = max(rc, swept)
        records_dir = os.path.join(results, experiment_name(entry, extra))
        follow_up = FOLLOW_UPS.get(entry.experiment)
        sweeps = []
        if follow_up and os.path.isdir(records_dir):
            if sweep_ran_through(records_dir, swept, started):
                sweeps = follow_up(compact.load_records(records_dir))
            else:  # cut short: the follow-ups would start from part of its runs
                print(f"{entry.experiment}: its sweep has runs without a record; the sweeps its report asks for are "
                      "not run (run the tier again)", flush=True)
        for overrides in sweeps:  # complete sweeps of their own: the entry's overrides are not added
            cmd = [sys.executable, "-m", "ddfbench", *overrides, f"out_dir={results}", "quiet=true", *(extra or [])]
            print("$", shell_line(cmd), flush=True)
            code = subprocess.run(cmd).returncode
            swept = max(swept, code if code >= 0 else 1)
        rc = max(rc, swept, write_report(entry, records_dir, swept))  # once its follow-ups have run: they read records
    return rc


def experiment_name(entry: Entry, extra: list[str] | None = None) -> str:
    """The records folder's name under out_dir that the entry's command line writes: the last experiment_name=
    of its overrides and then extra (Hydra takes the last), else its experiment YAML's, else the experiment."""
    named = [o.split("=", 1)[1] for o in [*entry.overrides, *(extra or [])] if o.startswith("experiment_name=")]
    if named:
        return named[-1]
    return str(OmegaConf.load(os.path.join(CONF_DIR, "experiment", f"{entry.experiment}.yaml")).get("experiment_name")
               or entry.experiment)


def shell_line(cmd: list[str]) -> str:
    """A command as a line to paste into a shell: `python -m ...` (the interpreter by its name), each word quoted
    where the shell needs it."""
    return shlex.join(["python", *cmd[1:]])


def write_report(entry: Entry, records_dir: str, swept: int) -> int:
    """Write the entry's report from records_dir: into its committed folder after a sweep that exited 0, else beside
    the records (records_dir/report), keeping the committed report and its records as they are. The report's exit
    code."""
    out = os.path.join(ROOT, entry.report)
    if swept != 0:
        out = os.path.join(records_dir, "report")
        print(f"{entry.experiment}: its sweep had failed jobs or was cut short (exit {swept}); {entry.report} is kept "
              f"as committed and the report of these records is written to {out} (fix the cause and run the tier "
              "again: finished runs are skipped)", flush=True)
    return subprocess.run([sys.executable, "-m", "ddfbench.report", records_dir, "--out", out]).returncode


def sweep_ran_through(records_dir: str, exit_code: int, since: float) -> bool:
    """Whether every job of the sweep started at `since` (epoch seconds) into records_dir has a record, ok or failed
    (a failure that repeats on every rerun, such as a divergence, must not hold a follow-up back). A sweep that wrote
    no grid of its own (multirun.yaml) since then stopped before its first job; there, and where its grid cannot be
    read, its exit code decides."""
    from ddfbench.report.status import newest_sweep, sweep_status

    grid = newest_sweep(records_dir)
    if grid is None or os.path.getmtime(grid) < since:
        return exit_code == 0
    try:
        return not sweep_status(records_dir, [grid]).missing
    except (InputError, OSError):
        return exit_code == 0


# modules of the stale scope that write nothing into a record: they check a job's input or the command's words before
# any work (a job they let through runs as before), print a sweep's progress, mirror records to MLflow, or end an
# orphaned worker
RESULT_NEUTRAL = ("ddfbench/run/checks.py", "ddfbench/run/overrides.py", "ddfbench/run/progress.py",
                  "ddfbench/run/tracking.py", "ddfbench/run/worker_guard.py")


def load_neutral(name: str) -> dict[str, str]:
    """{full commit hash: why} of conf/suite/<name>.yaml's `result_neutral`: commits that changed code of the stale
    scope but no measured value of a run; a one-line InputError naming the file and key when malformed. An entry that
    is not a commit of this clone (a shallow one) is left out with a line on stderr: it counts for nothing."""
    neutral = _suite_file(name).get("result_neutral") or {}
    where = f"conf/suite/{name}.yaml: result_neutral"
    if not isinstance(neutral, dict):
        raise InputError(f"{where}: needs {{commit: why the commit changes no measured value}}")
    out = {}
    for commit, why in neutral.items():
        if not re.fullmatch(r"[0-9a-f]{7,40}", str(commit)) or not isinstance(why, str) or not why.strip():
            raise InputError(f"{where}.{commit}: needs a commit (7 to 40 hex digits) and why it changes no "
                             "measured value")
        full = subprocess.run(["git", "-C", ROOT, "rev-parse", "--verify", "-q", f"{commit}^{{commit}}"],
                              capture_output=True, text=True)
        if full.returncode != 0:
            print(f"ddfbench.suite: {where}.{commit}: not a commit of this clone (a shallow clone?): not counted",
                  file=sys.stderr)
            continue
        out[full.stdout.strip()] = str(why)
    return out


def _only_neutral_commits(since: str, path: str, neutral: dict[str, str]) -> bool:
    """Whether every commit after `since` that touched path is one of the result-neutral ones (full hashes)."""
    log = subprocess.run(["git", "-C", ROOT, "log", "--format=%H", f"{since}..HEAD", "--", path],
                         capture_output=True, text=True)
    commits = log.stdout.split()
    return log.returncode == 0 and bool(commits) and all(c in neutral for c in commits)


def stale(entry: Entry, records: list[dict[str, Any]],
          neutral: dict[str, str] | None = None) -> tuple[str, list[str]]:
    """(the records' code commit(s), files of the models' families and configs changed or removed since the oldest
    one; a file added since is not a change to the code that ran, nor one whose every change since is a commit of
    `neutral`, load_neutral). ("", []) where no record names its code commit (records run outside a git
    checkout)."""
    shas = sorted({str((r.get("env") or {}).get("code_sha")) for r in records if (r.get("env") or {}).get("code_sha")})
    if not shas:
        return "", []
    # the mesh family renders every record's reference frame (render.mesh_reference), whatever the record's family
    paths = {"ddfbench/core", "ddfbench/truth", "ddfbench/sampling", "ddfbench/evaluate", "ddfbench/fit",
             "ddfbench/render", "ddfbench/run", "ddfbench/models/mesh.py", f"conf/experiment/{entry.experiment}.yaml"}
    paths |= {os.path.relpath(os.path.join(root, f), ROOT) for root, _, files in os.walk(os.path.join(ROOT, "ddfbench",
              "models")) for f in files if f.startswith("_") and f.endswith(".py") and f != "__init__.py"}
    for rec in records:
        family, model = str(rec.get("family")), str(rec.get("model"))
        paths |= {f"ddfbench/models/{family}", f"ddfbench/models/{family}.py", f"conf/model/{model}.yaml",
                  f"conf/model/{family}.yaml"}
    existing = sorted(p for p in paths if os.path.exists(os.path.join(ROOT, p)))
    existing += [f":(exclude){p}" for p in RESULT_NEUTRAL]
    changed = []
    for sha in shas:
        # a file added since cannot change what the records' code did (what uses it changed too): not counted
        done = subprocess.run(["git", "-C", ROOT, "diff", "--name-only", "--diff-filter=a", sha, "HEAD", "--", *existing],
                              capture_output=True, text=True)
        if done.returncode != 0:
            return ", ".join(s[:7] for s in shas), [f"commit {sha[:7]} is not in this clone"]
        # neutral commits count only where sha is an ancestor of HEAD: else the difference holds changes of sha's
        # side, which no list of HEAD's commits covers
        ancestor = neutral and subprocess.run(["git", "-C", ROOT, "merge-base", "--is-ancestor", sha, "HEAD"],
                                              capture_output=True).returncode == 0
        changed += [path for path in done.stdout.split() if not _only_membership_changed(sha, path)
                    and not (ancestor and _only_neutral_commits(sha, path, neutral))]
    return ", ".join(s[:7] for s in shas), sorted(set(changed))


def _only_membership_changed(sha: str, path: str) -> bool:
    """Whether a plugin YAML changed only in its `experiments` part (which experiments it joins, its levels there):
    the config a finished run used is the same."""
    if not (path.startswith("conf/") and path.endswith(".yaml")):
        return False
    old = subprocess.run(["git", "-C", ROOT, "show", f"{sha}:{path}"], capture_output=True, text=True)
    if old.returncode != 0 or not os.path.isfile(os.path.join(ROOT, path)):
        return False
    before, after = OmegaConf.create(old.stdout), OmegaConf.load(os.path.join(ROOT, path))
    for cfg in (before, after):
        cfg.pop(plugins.META_KEY, None)
    return before == after


def status(suite: str) -> int:
    """Print each report of the suite with its records' commit and whether it is stale; 1 when any is stale or
    unknown."""
    records = committed_records(os.path.join(ROOT, "reports"))
    neutral = load_neutral(suite)
    worst = 0
    for tier, entries in load_suite(suite).items():
        for entry in entries:
            recs = records.get(entry.report, [])
            commits, changed = stale(entry, recs, neutral) if recs else ("", [])
            state = "stale" if changed else ("current" if commits else "unknown")
            worst = max(worst, 1 if state != "current" else 0)
            print(f"{tier:<5} {entry.experiment:<16} {entry.report:<28} {state:<8} "
                  + (f"records of {commits}" if commits else
                     "records that name no code commit" if recs else "no records committed")
                  + (f"; changed since: {', '.join(changed[:4])}{' ...' if len(changed) > 4 else ''}" if changed else ""))
    for commit, why in neutral.items():
        print(f"not counted, result-neutral (conf/suite/{suite}.yaml): {commit[:7]}: {why}")
    return worst


def check_checkout() -> None:
    """The suite plans from, judges and writes the committed reports/ of a git checkout of ddfbench (ROOT): a one-line
    InputError where ROOT is not the top of one (a wheel installed into site-packages)."""
    check_conf_found()
    if not os.path.exists(os.path.join(ROOT, ".git")):  # a folder; in a git worktree, a file
        raise InputError(f"{ROOT}: not the top of a git checkout of ddfbench; the suite reads and writes the "
                         "committed reports/ of one (git clone the repository, then pip install -e . in it)")


def command(args: argparse.Namespace, overrides: list[str]) -> int:
    """The exit code of the command args names (status, run or its --dry-run plan)."""
    check_checkout()
    if args.command == "status":
        return status(args.suite)
    only = [n for n in (args.only or "").split(",") if n] or None
    if args.only is not None and only is None:
        raise InputError(f"--only {args.only!r}: names no experiment")
    if args.dry_run:
        print_plan(plan(args.suite, args.tier, only=only, extra=overrides))
        return 0
    return run(args.suite, args.tier, args.results, overrides, args.from_reports, only)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m ddfbench.suite", description=" ".join(__doc__.split("\n")[:2]))
    sub = parser.add_subparsers(dest="command", required=True)
    run_p = sub.add_parser("run", help="run a tier (or print its plan with --dry-run)",
                           epilog="Hydra overrides after `--` go to every experiment's command line, e.g. "
                                  "`-- threads=1 hydra/launcher=local_parallel`.")
    run_p.add_argument("suite", help="the suite file conf/suite/<SUITE>.yaml (e.g. v1)")
    run_p.add_argument("--tier", required=True, help="a tier of the suite file (v1: core, long, gpu)")
    run_p.add_argument("--dry-run", action="store_true",
                       help="print the jobs per model and the estimated CPU-hours per experiment; run nothing")
    run_p.add_argument("--results", default="results", help="out_dir of the runs (default: results)")
    run_p.add_argument("--only", help="comma-separated experiments of the tier to run or plan (default: all)")
    run_p.add_argument("--from-reports", action="store_true",
                       help="first restore each report's committed records into --results: finished runs are "
                            "skipped and the report is written from all of them (resume a tier across machines)")
    status_p = sub.add_parser("status", help="which reports are stale")
    status_p.add_argument("suite", help="the suite file conf/suite/<SUITE>.yaml (e.g. v1)")
    argv = sys.argv[1:] if argv is None else argv
    overrides = argv[argv.index("--") + 1:] if "--" in argv else []  # Hydra overrides for every experiment's command
    args = parser.parse_args(argv[:argv.index("--")] if "--" in argv else argv)
    try:
        code = command(args, overrides)
        sys.stdout.flush()  # here, so that a reader gone away is caught below and not at the interpreter's exit
        return code
    except InputError as exc:
        print(f"ddfbench.suite: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("ddfbench.suite: interrupted; run the same command again to go on (finished runs are skipped)",
              file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (`| head`): stop printing, quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1

