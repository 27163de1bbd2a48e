"""Command line: `python -m ddfbench [overrides]` (Hydra). A thin wrapper around runner.run.

Without `model=` or `+experiment=` it runs `+experiment=default` (every family, small budget) with the
given overrides, so `python -m ddfbench shape=cow` compares every family on the cow.
A single run that fails exits non-zero with a one-line error; in a sweep a failure is a `failed`
record and the sweep goes on, then exits 1. A command-line value that a job's level would replace stops the command
(check_levels_keep). Nothing here holds module-level state (launchers pickle the task).
"""

from __future__ import annotations

import logging
import os
import re
import sys
from typing import Any

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.experimental.callback import Callback
from hydra.types import RunMode
from omegaconf import DictConfig, ListConfig, OmegaConf

from ddfbench.core import plugins
from ddfbench.core.plugins import CONF_DIR  # plugins registers the `members` resolver the experiments use
from ddfbench.run.overrides import MULTIRUN_FLAGS, check_overrides, check_shape_path, values_of

INTERRUPTED = ("interrupted; run the same command again to go on (finished runs are skipped, a fit resumes from its "
               "last checkpoint)")
KEY_FILE = "ddfbench_key.txt"  # written in each Hydra job folder: which record the job produced


@hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="config")
def task(cfg: DictConfig) -> str | float:
    """One Hydra job: resolve the config, run it, return the record key (with `objective` set: that
    metric of the record, for an optimizing sweeper)."""
    from ddfbench.core.errors import InputError
    from ddfbench.report.tables import console_table, summarize
    from ddfbench.run import launch, runner, runs
    from ddfbench.run.worker_guard import watch_launcher

    watch_launcher()  # a local_parallel worker stops with its sweep
    hc = HydraConfig.get()
    plain: dict[str, Any] = OmegaConf.to_container(cfg, resolve=True)  # type: ignore[assignment]
    try:  # a setting of the whole command (threads, experiment_name): one line and stop, before any run
        plain["threads"], device = launch.job_settings(plain, hc)
        check_levels_keep(plain, dict(hc.runtime.choices), list(hc.overrides.task))
        record = runner.run(plain, choices=dict(hc.runtime.choices), overrides=list(hc.overrides.task), device=device)
    except InputError as err:
        print(f"ddfbench: {err}", file=sys.stderr)
        sys.exit(1)
    try:
        with open(os.path.join(hc.runtime.output_dir, KEY_FILE), "w") as fh:
            fh.write(f"{record['experiment']}/{record['key']}\n")
    except OSError:  # a full disk: the sweep's closing table leaves this job out, the record (if any) stands
        pass
    if hc.mode == RunMode.MULTIRUN:
        from ddfbench.run.progress import job_finished

        if (text := job_finished(os.path.dirname(hc.runtime.output_dir), record)) is not None:
            print(text, flush=True)
    if hc.mode == RunMode.RUN:
        if not cfg.get("quiet", False) and record["status"] == "ok":  # a failure is the one line below
            folder = runs.run_dir(str(cfg.get("out_dir", "results")), record["experiment"], record["key"])
            print(console_table(summarize([record])) + f"record: {os.path.join(folder, runs.RECORD_FILE)}")
        if record["status"] != "ok":
            print(f"ddfbench: {record['error']}", file=sys.stderr)
            sys.exit(1)
    if cfg.get("objective"):
        from ddfbench.evaluate.metric_registry import objective_value

        return objective_value(record, str(cfg.objective))
    return record["key"]


def sweep_direction(value: Any) -> str:
    """An optimizing sweeper's `direction` as written ("minimize" | "maximize"): Optuna's default is its Direction
    enum (str() would read "Direction.minimize"), and a list of one direction is a one-objective study."""
    if isinstance(value, (list, ListConfig)) and len(value) == 1:
        value = value[0]
    return str(getattr(value, "name", value))


class SweepTableCallback(Callback):
    """Sweep progress lines (ddfbench.run.progress) and, at the end of a sweep, the table of its records; a sweep with
    a failed job exits 1 once every job has run, with one line naming how many failed and the first one's error."""

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        from ddfbench.core.errors import InputError
        from ddfbench.evaluate.metric_registry import check_objective
        from ddfbench.run.progress import count_jobs, start_sweep

        try:
            check_sweep_levels(config)
            if config.get("objective") and config.hydra.sweeper.get("direction") is not None:
                check_objective(str(config.objective), sweep_direction(config.hydra.sweeper.direction))
        except InputError as err:
            print(f"ddfbench: {err}", file=sys.stderr)
            sys.exit(1)

        sweeper = config.hydra.sweeper
        total = count_jobs(list(config.hydra.overrides.task), sweeper.get("params"), sweeper.get("n_trials"))
        try:
            start_sweep(str(config.hydra.sweep.dir), total)
        except OSError as err:  # a full or read-only disk, before any job
            print(f"ddfbench: {err.filename or config.hydra.sweep.dir}: cannot be written ({err.strerror or err}); "
                  "nothing ran", file=sys.stderr)
            sys.exit(1)
        if config.get("quiet", False) or os.environ.get("CI"):  # CI logs: only the progress lines
            for launcher_log in ("hydra", "hydra_plugins"):
                logging.getLogger(launcher_log).setLevel(logging.WARNING)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        from ddfbench.report.records import distinct_shape_names
        from ddfbench.report.tables import console_table, summarize
        from ddfbench.run.progress import sweep_total
        from ddfbench.run.runs import RECORD_FILE, read_record

        sweep_dir, out_dir = str(config.hydra.sweep.dir), str(config.get("out_dir", "results"))
        records = []
        jobs = os.listdir(sweep_dir) if os.path.isdir(sweep_dir) else []
        for job in sorted(jobs, key=lambda j: (not j.isdigit(), int(j) if j.isdigit() else 0, j)):  # 2 before 10
            key_file = os.path.join(sweep_dir, job, KEY_FILE)
            if os.path.exists(key_file):
                with open(key_file) as fh:
                    rec = read_record(os.path.join(out_dir, fh.read().strip(), RECORD_FILE))
                if rec:
                    records.append(rec)
        if records and not config.get("quiet", False):
            folder = os.path.join(out_dir, str(records[0]["experiment"]))
            print(console_table(summarize(distinct_shape_names(records))) + f"records: {folder}\n"
                  f"full table, plots and gallery: python -m ddfbench.report {folder}   (writes {folder}/report)")
        failed = [r for r in records if r.get("status") != "ok"]
        total = max(sweep_total(sweep_dir) or 0, len(records))
        missing = total - len(records)  # a job that could not write its record, or was killed before it did
        if failed or missing:
            parts = [f"{missing} left no record"] if missing else []
            if failed:
                first = failed[0]
                parts.append(f"first: {first.get('model')} on {(first.get('shape') or {}).get('name')}: "
                             f"{first.get('error')}")
            print(f"ddfbench: {len(failed) + missing} of {total} jobs failed ({'; '.join(parts)})", file=sys.stderr)
            sys.exit(1)


def wants_default_experiment(args: list[str]) -> bool:
    """True when the command names no model, no experiment and no Hydra flag: run every family."""
    named = ("model=", "+model=", "experiment=", "+experiment=", "-")
    return not any(a.startswith(named) for a in args)


def sweeps(args: list[str]) -> bool:
    """Whether the command runs a sweep: -m, else an experiment (each sets MULTIRUN) or the default run, unless
    hydra.mode=RUN."""
    if any(a in MULTIRUN_FLAGS for a in args):
        return True
    return "hydra.mode=RUN" not in args and (bool(values_of(args, "experiment")) or wants_default_experiment(args))


def _chosen(group: str, args: list[str]) -> list[str] | None:
    """The configs of `group` the command names: one (`model=ddf_paper`) or a plain list (`model=mesh,grid_sdf`);
    None where it names none or a glob, range or interpolation (an experiment's own list: any config may run)."""
    chosen = values_of(args, group)
    if len(chosen) == 1 and re.fullmatch(r"[\w.-]+(,[\w.-]+)*", chosen[0]):
        return chosen[0].split(",")
    return None


def _config_keys(group: str, name: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """(keys a `<group>.<key>=` override may set for config `name`: its own and, for a model, its family's; the keys
    its own YAML holds)."""
    own = plugins.defaults(group, name)
    return (plugins.model_defaults(name) if group == "model" else own), own


def checked_overrides(args: list[str]) -> list[str]:
    """args with each `model.<key>=` / `sampling.<key>=` checked against the plugin's known keys.

    An unknown key is a one-line InputError naming it and the known keys: those of every config the command names
    (in a list `model=mesh,grid_sdf`, a key one of them lacks is refused naming it, before any job), else of any
    config. A key the family has but a chosen preset's YAML leaves to the family's defaults (model=ddf_paper
    model.entry_share=0.3) is passed as `++model.<key>=`, so Hydra adds it instead of refusing it.
    """
    from ddfbench.core.errors import InputError

    out = []
    for arg in args:
        path, _, value = arg.lstrip("+").partition("=")
        group, _, key = path.partition(".")
        if not _ or group not in plugins.NAME_KEYS or not key:
            out.append(arg)
            continue
        root, names = key.split(".")[0], _chosen(group, args)
        keys = {name: _config_keys(group, name) for name in names or plugins.names(group)}
        plugins.strict_keys(group, {root: value}, {k: v for known, _ in keys.values() for k, v in known.items()},
                            near=True)  # a key no config that may run has
        if names is None:  # an experiment's configs: each job checks its own (ddfbench.run.checks)
            out.append(arg)
            continue
        for name, (known, _) in keys.items():
            if root not in known:
                raise InputError(f"{path}: {group}={name} of this sweep has no key {root!r} (known: "
                                 f"{', '.join(sorted(known))}); sweep the {group}s that have it in their own command")
        lacking = any(root not in own for _, own in keys.values())
        out.append(f"++{path}={value}" if lacking and not arg.startswith("+") else arg)
    return out


def _at(cfg: Any, path: str) -> tuple[bool, Any]:
    """(found, value) of a dotted key in a plain nested dict."""
    for part in path.split("."):
        if not isinstance(cfg, dict) or part not in cfg:
            return False, None
        cfg = cfg[part]
    return True, cfg


def _both_nan(a: Any, b: Any) -> bool:
    return isinstance(a, float) and isinstance(b, float) and a != a and b != b


# the overrides that decide what a job's levels set: a plugin group's choice and the key that picks its level
LEVEL_CHOICES = (*plugins.LEVEL_KEYS, *plugins.LEVEL_KEYS.values())


def _set_key(override: str, choices: dict[str, str]) -> str | None:
    """The config key a command-line `key=value` sets, or None for what a level cannot replace: a config group's
    choice, a level's own key, a Hydra setting, a deletion."""
    key, eq, _ = override.lstrip("+").partition("=")
    if not eq or override.startswith("~") or key in choices or key in LEVEL_CHOICES or key.startswith("hydra"):
        return None
    return key


def check_levels_keep(cfg: dict[str, Any], choices: dict[str, str], overrides: list[str]) -> None:
    """A one-line InputError when a `key=value` of the command line is replaced by the level the job applies
    (plugins.job_config: e.g. ddf_tuned's `first_look` sets train.max_steps for the default run), which would run
    another value than the one given. cfg: the resolved job config before its levels; choices: Hydra's group
    choices; overrides: the job's command-line overrides. A level the job's model or sampler lacks is runner.run's
    to report."""
    from ddfbench.core.errors import InputError

    try:
        leveled = plugins.job_config(cfg, choices)
    except InputError:
        return
    for arg in overrides:
        path = _set_key(arg, choices)
        if path is None:
            continue
        given = arg.partition("=")[2]
        (found, asked), (_, ran) = _at(cfg, path), _at(leveled, path)
        if found and asked != ran and not _both_nan(asked, ran):  # nan: the value checks name it
            keys = [k for k in plugins.LEVEL_KEYS.values() if cfg.get(k) is not None]
            raise InputError(f"{path}={given}: the level {' '.join(f'{k}={cfg[k]}' for k in keys)} of experiment "
                             f"{cfg.get('experiment_name')} sets {path} to {ran} for model {choices.get('model')}, "
                             f"which would replace the value given (drop it, or run without the levels: "
                             f"{' '.join(f'{k}=null' for k in keys)})")


def check_plain_keys(args: list[str]) -> None:
    """A one-line InputError, with the near-miss names, for a `key=` or `train|eval|oracle|scene.key=` override
    without `+` that nothing declares (`train.max_step=5`, `scene.widht=3`), which Hydra would refuse in several
    lines, and for a `+train|eval|oracle.key=` that nothing reads (`+train.max_step=5`: every job would refuse it,
    ddfbench.run.checks.check_known_keys); the other `+` forms are checked per job (check_known_keys,
    render.scene)."""
    from ddfbench.core.errors import InputError
    from ddfbench.run.checks import CHECKED_SECTIONS, declared_keys

    known = declared_keys()
    for arg in args:
        path, eq, value = arg.partition("=")
        section, _, key = path.lstrip("+").partition(".")
        if arg.startswith("+") and eq and key and section in CHECKED_SECTIONS:
            plugins.strict_keys(section, {key.split(".")[0]: value}, dict.fromkeys(known[section]), near=True)
            continue
        if not eq or arg.startswith(("+", "~", "-")) or "/" in path or path.startswith("hydra."):
            continue
        if not key and section not in (*known[""], "suite") and os.path.isdir(os.path.join(CONF_DIR, section)):
            raise InputError(f"{arg}: {section} is a config group outside the defaults: use +{arg}")
        if not key:
            plugins.strict_keys("", {section: value}, dict.fromkeys(known[""]), near=True)
        elif section in CHECKED_SECTIONS:
            plugins.strict_keys(section, {key.split(".")[0]: value}, dict.fromkeys(known[section]), near=True)
        elif section == "scene":  # the keys every scene preset shares (conf/scene/*.yaml)
            scene_keys = {k for name in plugins.names("scene") for k in plugins.defaults("scene", name)} - {"defaults"}
            plugins.strict_keys(section, {key.split(".")[0]: value}, dict.fromkeys(scene_keys), near=True)


def check_sweep_levels(config: DictConfig) -> None:
    """check_levels_keep for every job of a basic sweep, before the first one runs: one job composed per distinct
    model, sampler, level and swept plain value. Only when the command line sets a plain key (the sweep's own
    settings are the experiment's); another sweeper's jobs are checked each as it starts (task)."""
    from hydra.core.global_hydra import GlobalHydra

    from ddfbench.report.status import compose_plain, sweep_jobs

    task = list(config.hydra.overrides.task)
    choices = dict(config.hydra.runtime.choices)
    plain = {key for o in task if (key := _set_key(o, choices)) is not None}
    if not plain or not str(config.hydra.sweeper.get("_target_", "")).endswith("BasicSweeper"):
        return
    loader = GlobalHydra.instance().config_loader()
    seen = set()
    for job in sweep_jobs(loader, config, task)[1]:
        what = tuple(o for o in job if o.lstrip("+").split("=", 1)[0] in (*LEVEL_CHOICES, *plain))
        if what not in seen:
            seen.add(what)
            check_levels_keep(*compose_plain(loader, config, job), job)


EXTRA_OF_EXPERIMENT = {"tune": ("optuna", "tune")}  # experiment -> (module it needs, pip extra that installs it)


def check_extras(args: list[str]) -> None:
    """A one-line InputError when the experiment named in args needs an extra that is not installed."""
    import importlib.util

    from ddfbench.core.errors import InputError

    for name in values_of(args, "experiment"):
        if name in EXTRA_OF_EXPERIMENT and importlib.util.find_spec(EXTRA_OF_EXPERIMENT[name][0]) is None:
            raise InputError(f"+experiment={name}: needs the `{EXTRA_OF_EXPERIMENT[name][1]}` extra "
                             f"(pip install -e \".[{EXTRA_OF_EXPERIMENT[name][1]}]\")")


def check_tune(args: list[str]) -> None:
    """+experiment=tune studies one model: a one-line InputError when the command names none, or one whose YAML
    declares no search space (the Optuna sweeper would end in a traceback)."""
    if "tune" not in values_of(args, "experiment"):
        return
    from ddfbench.core.errors import InputError
    from ddfbench.fit.tune import EXPERIMENT, search_space

    models = values_of(args, "model")
    studied = ", ".join(plugins.members("model", EXPERIMENT))
    if len(models) != 1 or "," in models[0]:
        raise InputError(f"+experiment={EXPERIMENT}: name one model to study (model=<name>; models with a search "
                         f"space: {studied})")
    if models[0] in plugins.names("model") and not search_space(models[0]):
        raise InputError(f"model={models[0]}: conf/model/{models[0]}.yaml declares no experiments.{EXPERIMENT} search "
                         f"space (models that do: {studied})")


def check_out_dir(args: list[str]) -> None:
    """A one-line InputError, before Hydra writes its own files there, when the out_dir the command names (the
    last `out_dir=`, else conf/config.yaml's `results`) is not a folder that can be made and written."""
    from ddfbench.core.errors import InputError

    if any(a in ("-h", "--help", "-c", "--cfg", "--info", "--hydra-help") for a in args):  # nothing runs
        return
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    out_dir: object = "results"  # conf/config.yaml's
    for arg in (a for a in args if a.lstrip("+").startswith("out_dir=")):
        try:  # the value as Hydra reads it ('my results' is my results; null is None)
            (override,) = OverridesParser.create().parse_overrides([arg])
        except HydraException:
            return  # Hydra says what is wrong with it
        if override.is_sweep_override():
            return  # a sweep of folders: each job's runner reports its own
        out_dir = override.value()
    if not isinstance(out_dir, str):
        raise InputError(f"out_dir={out_dir!r}: must name a folder")
    if "${" not in out_dir:  # an interpolation: the job's runner reports it
        from ddfbench.run.checks import writable_folder

        writable_folder(out_dir, "out_dir=")


def experiment_help(args: list[str]) -> str | None:
    """`--help` with `+experiment=NAME`: the experiment file's own description (its header comment), what its
    sweep varies and how many jobs these arguments give; None without an experiment (Hydra's page then)."""
    names = values_of(args, "experiment")
    if not names:
        return None
    from ddfbench.core.errors import InputError
    from ddfbench.report.status import expected_grid

    path = os.path.join(CONF_DIR, "experiment", f"{names[-1]}.yaml")
    if not os.path.isfile(path):
        return None  # Hydra names the missing file
    with open(path) as fh:
        header = [line[2:].rstrip() for line in fh if line.startswith("# ") and "@package" not in line]
    given = [a for a in args if a not in ("-h", "--help") and not a.startswith(("-m", "--multirun"))]
    try:
        jobs, _ = expected_grid(os.path.join(CONF_DIR, "no_records"), given)
        swept = sorted({o.split("=", 1)[0] for job in jobs for o in job.swept})
        plan = f"sweep over: {', '.join(swept) or 'nothing (one job)'}; {len(jobs)} jobs with these arguments"
    except InputError as err:  # an optimizing sweeper (tune) or an override the grid cannot expand
        plan = f"sweep: not expanded here ({err})"
    return "\n".join([f"python -m ddfbench {' '.join(given)}", "", *header, "", plan,
                      "Hydra's own help: --hydra-help"]) + "\n"


def check_threads(args: list[str]) -> None:
    """A one-line InputError for a `threads=` override that is not an integer >= 0 (null or empty: 0), before
    Hydra starts, so that every launcher reports it alike. A sweep, an interpolation and a value Hydra cannot
    parse are left to Hydra and to launch.job_settings, which checks each job's value."""
    from hydra.core.override_parser.overrides_parser import OverridesParser
    from hydra.errors import HydraException

    from ddfbench.core.errors import checked_int

    for arg in args:
        if not arg.startswith("threads="):
            continue
        try:
            (override,) = OverridesParser.create().parse_overrides([arg])
        except HydraException:
            continue
        value = None if override.is_sweep_override() else override.value()
        if value not in (None, "") and not (isinstance(value, str) and "${" in value):
            checked_int(value, "threads", 0)


OPENMP_SPIN = "1000"  # GOMP_SPINCOUNT: spins of a waiting OpenMP thread before it sleeps (libgomp's default 300,000)


def short_openmp_spin() -> None:
    """Set GOMP_SPINCOUNT to OPENMP_SPIN, before torch loads libgomp, unless the environment sets a wait policy.
    On a machine other processes keep busy, threads spinning at a barrier take the cores the working threads need.
    2-core machine beside 2 busy processes, ddf_tuned 1,500 steps at threads=0 (2 threads): fit 21-241 s with
    libgomp's default spin (3 runs), 12.7-16.8 s with 1,000 (8 runs), 11.4-12.4 s at threads=1. Idle, medians of 4
    alternating runs: 4.4 s with the default spin, 4.7 s with 1,000."""
    if "OMP_WAIT_POLICY" not in os.environ and "GOMP_SPINCOUNT" not in os.environ:
        os.environ["GOMP_SPINCOUNT"] = OPENMP_SPIN


def main() -> None:
    """Entry point. Without `model=` or `+experiment=`, run `+experiment=default` with the given overrides."""
    from ddfbench.core.errors import InputError
    from ddfbench.run.checks import check_conf_found

    short_openmp_spin()  # first: the checks below import torch
    try:
        check_conf_found()
        check_extras(sys.argv[1:])
        check_threads(sys.argv[1:])
        check_out_dir(sys.argv[1:])
        check_plain_keys(sys.argv[1:])
        check_overrides(sys.argv[1:], sweeps=sweeps(sys.argv[1:]))
        check_shape_path(sys.argv[1:])
        check_tune(sys.argv[1:])
        sys.argv[1:] = checked_overrides(sys.argv[1:])
    except InputError as err:
        print(f"ddfbench: {err}", file=sys.stderr)
        sys.exit(1)
    if wants_default_experiment(sys.argv[1:]):
        sys.argv.append("+experiment=default")
    if any(a in ("-h", "--help") for a in sys.argv[1:]) and (text := experiment_help(sys.argv[1:])) is not None:
        print(text, end="")
        return
    try:
        task()
    except KeyboardInterrupt:
        print(f"ddfbench: {INTERRUPTED}", file=sys.stderr)
        sys.exit(130)
