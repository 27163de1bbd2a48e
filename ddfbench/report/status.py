"""`python -m ddfbench.report <records> --status [OVERRIDE ...]`: which runs of a sweep are done,
failed or missing.

The expected grid is the sweep's own: Hydra composes the experiment with the sweep's overrides, the
sweeper's params and the command-line sweep lists are expanded as Hydra's basic sweeper expands
them, and each job's resolved config is hashed into the key its record is stored under
(`runs.config_key`). Records are looked up by key anywhere below the records folder, whichever
sweep, launcher or machine wrote them; nothing depends on Hydra's end-of-sweep callback.

The sweep's overrides are those given after --status, else the newest
<out_dir>/.hydra/sweep/*/multirun.yaml of this experiment (<records> = <out_dir>/<experiment_name>),
else `+experiment=<name of the records folder>`.
"""

from __future__ import annotations

import glob
import os
import sys
from dataclasses import dataclass, field
from typing import Any

from omegaconf import DictConfig, OmegaConf, open_dict

from ddfbench.core import plugins
from ddfbench.core.errors import InputError, one_line
from ddfbench.core.plugins import CONF_DIR
from ddfbench.run import runs

LAUNCHER_PREFIXES = ("hydra/launcher", "hydra.launcher")  # cannot change a run; its plugin may be absent here


@dataclass
class Job:
    """One run of the grid: the overrides that vary across the sweep, and its record key."""

    swept: list[str]
    key: str


@dataclass
class SweepStatus:
    """The grid against the records: done, failed (with each record's one-line error), missing."""

    source: str
    expected: list[Job]
    done: list[Job] = field(default_factory=list)
    failed: list[tuple[Job, str]] = field(default_factory=list)
    missing: list[Job] = field(default_factory=list)
    other_records: int = 0  # records below the folder that are not part of this grid

    @property
    def complete(self) -> bool:
        return not self.failed and not self.missing


def _without_launcher(overrides: list[str]) -> list[str]:
    return [o for o in overrides if not o.lstrip("+~").startswith(LAUNCHER_PREFIXES)]


def load_sweep_file(path: str) -> DictConfig:
    """A sweep's multirun.yaml; a one-line InputError naming it where it is no YAML mapping (a sweep killed or out
    of disk while Hydra wrote it)."""
    try:
        found = OmegaConf.load(path)
    except Exception as exc:  # yaml's parse errors, not UTF-8, unreadable
        raise InputError(f"{path}: not a readable sweep file ({one_line(exc)})") from None
    if not isinstance(found, DictConfig):
        raise InputError(f"{path}: not a readable sweep file (a YAML {type(found).__name__}, not a mapping)")
    return found


def newest_sweep(records_dir: str) -> str | None:
    """The newest multirun.yaml beside records_dir whose experiment_name is the folder's name; one that cannot be read
    is passed over with a line on stderr naming it."""
    name = os.path.basename(os.path.normpath(records_dir))
    pattern = os.path.join(os.path.dirname(os.path.abspath(records_dir)), ".hydra", "sweep", "*", "multirun.yaml")
    for path in sorted(glob.glob(pattern), key=os.path.getmtime, reverse=True):
        try:
            found = load_sweep_file(path)
        except InputError as exc:
            print(f"ddfbench: skipped {exc}", file=sys.stderr)
            continue
        if found.get("experiment_name") == name:
            return path
    return None


def _master_config(loader: Any, records_dir: str, overrides: list[str]) -> tuple[DictConfig, str]:
    """The sweep's master config (hydra node included) and a line saying where it came from."""
    from hydra.types import RunMode

    if len(overrides) == 1 and overrides[0].endswith(".yaml") and os.path.isfile(overrides[0]):
        sweep_file: str | None = overrides[0]
    elif overrides:
        sweep_file = None
    else:
        sweep_file = newest_sweep(records_dir)
    if sweep_file is not None:
        master = load_sweep_file(sweep_file)
        with open_dict(master):
            master.hydra.overrides.hydra = _without_launcher(list(master.hydra.overrides.hydra))
        return master, f"the sweep of {sweep_file}"
    if not overrides:
        name = os.path.basename(os.path.normpath(records_dir))
        if not os.path.isfile(os.path.join(CONF_DIR, "experiment", f"{name}.yaml")):
            raise InputError(f"{records_dir}: no sweep of experiment '{name}' found beside it and no "
                             f"conf/experiment/{name}.yaml; pass the sweep's overrides after --status")
        overrides = [f"+experiment={name}"]
    master = loader.load_configuration("config", _without_launcher(overrides), run_mode=RunMode.MULTIRUN)
    return master, "the overrides " + " ".join(overrides)


def sweep_jobs(loader: Any, master: DictConfig, overrides: list[str]) -> tuple[set[str], list[list[str]]]:
    """(the keys the sweep varies, each job's overrides in Hydra's order) as Hydra's basic sweeper expands the master
    config's sweep params and then overrides (an override of a params key replaces it)."""
    from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
    from hydra.core.override_parser.overrides_parser import OverridesParser

    params = [f"{k}={v}" for k, v in (master.hydra.sweeper.get("params") or {}).items()]
    parsed = OverridesParser.create(config_loader=loader).parse_overrides(params + overrides)
    swept = {o.get_key_element() for o in parsed if o.is_sweep_override()}
    return swept, [list(job) for batch in BasicSweeper.split_arguments(parsed, None) for job in batch]


def expected_grid(records_dir: str, overrides: list[str]) -> tuple[list[Job], str]:
    """Every job of the sweep (in Hydra's order) with its record key, and where the grid came from."""
    from hydra import initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    from ddfbench.run.checks import check_job  # (it imports the families: torch)

    with initialize_config_dir(CONF_DIR, version_base="1.3", job_name="ddfbench_status"):
        loader = GlobalHydra.instance().config_loader()
        master, source = _master_config(loader, records_dir, overrides)
        if not str(master.hydra.sweeper.get("_target_", "")).endswith("BasicSweeper"):
            raise InputError(f"hydra.sweeper={master.hydra.sweeper._target_}: --status expands only Hydra's basic sweeper")
        swept, expanded = sweep_jobs(loader, master, list(master.hydra.overrides.task))
        jobs = []
        for job_overrides in expanded:
            cfg = compose_job(loader, master, job_overrides)[0]
            if not jobs:  # the runner's checks, once: an override it refuses (+train.max_step=5) runs no job
                check_job(cfg)
            jobs.append(Job([o for o in job_overrides if o.split("=", 1)[0] in swept], runs.config_key(cfg)))
    return jobs, source


def compose_plain(loader: Any, master: DictConfig, overrides: list[str]) -> tuple[dict[str, Any], dict[str, str]]:
    """One job of a sweep as the job itself resolves it, before its levels: (its resolved config without the hydra
    node, Hydra's config-group choices). HydraConfig is left as it was found (the sweep's own, in a callback)."""
    from hydra.core.hydra_config import HydraConfig

    before = HydraConfig.instance().cfg
    cfg = loader.load_sweep_config(master, overrides)
    try:
        HydraConfig.instance().set_config(cfg)  # as the job itself resolves its interpolations
        choices = dict(cfg.hydra.runtime.choices)
        with open_dict(cfg):
            del cfg["hydra"]
        return OmegaConf.to_container(cfg, resolve=True), choices  # type: ignore[return-value]
    finally:
        HydraConfig.instance().cfg = before


def compose_job(loader: Any, master: DictConfig, overrides: list[str]) -> tuple[dict[str, Any], dict[str, str]]:
    """One job of a sweep as the job itself sees it: (its resolved config with its levels applied,
    plugins.job_config, what its record key is taken from; Hydra's config-group choices)."""
    cfg, choices = compose_plain(loader, master, overrides)
    return plugins.job_config(cfg, choices), choices


def sweep_status(records_dir: str, overrides: list[str] | None = None,
                 records: list[dict[str, Any]] | None = None) -> SweepStatus:
    """Match the expected grid against the records found anywhere below records_dir (or `records`, already read
    from there: their problems are said once)."""
    jobs, source = expected_grid(records_dir, list(overrides or []))
    found: dict[str, dict[str, Any]] = {}
    if records is None:
        records = runs.find_records(records_dir) if os.path.isdir(records_dir) else []
    for rec in records:
        if rec.get("status") == "ok" or rec.get("key") not in found:  # an ok copy wins over a failed one
            found[str(rec.get("key"))] = rec
    status = SweepStatus(source=source, expected=jobs)
    for job in jobs:
        rec = found.get(job.key)
        if rec is None:
            status.missing.append(job)
        elif rec.get("status") == "ok":
            status.done.append(job)
        else:
            status.failed.append((job, str(rec.get("error") or "failed (no error message)")))
    status.other_records = len(set(found) - {j.key for j in jobs})
    return status


def format_status(records_dir: str, status: SweepStatus) -> str:
    """A summary line, then one line per failed run (its error) and per missing run."""
    lines = [f"{records_dir}: {len(status.expected)} runs expected from {status.source}",
             f"done {len(status.done)}  failed {len(status.failed)}  missing {len(status.missing)}"]
    lines += [f"failed   {' '.join(job.swept) or '(single run)'}  [{job.key}]  {error}" for job, error in status.failed]
    lines += [f"missing  {' '.join(job.swept) or '(single run)'}  [{job.key}]" for job in status.missing]
    if status.other_records:
        lines.append(f"({status.other_records} other records below {records_dir} are not part of this grid)")
    return "\n".join(lines)


def main(records_dir: str, overrides: list[str]) -> int:
    """Print the status; exit code 0 when every run is done, 1 when some failed or are missing, 2 on bad input."""
    from hydra.errors import HydraException

    try:
        status = sweep_status(records_dir, overrides)
    except (InputError, HydraException) as exc:
        print(f"ddfbench.report --status: {str(exc).strip().splitlines()[0]}", file=sys.stderr)
        return 2
    print(format_status(records_dir, status))
    return 0 if status.complete else 1
