"""Optional MLflow tracking: one ddfbench record → one MLflow run (`tracking=mlflow`, extra `tracking`).

The JSON record stays the source of truth. `track(record, ...)` is called after the record is
published; whatever goes wrong in MLflow (package missing, server down, bad URI) becomes one
warning line on stderr and the run keeps its record. Logging is idempotent: every MLflow run is
tagged with the record key and the record's `finished` time, and a record already logged (a resumed
sweep skipping an ok run, a second backfill) is not logged again.

What one MLflow run holds (MLflow experiment = the ddfbench experiment name):
  params     the record's semantic config, flattened with "." (model.hidden, train.max_seconds, ...)
  tags       ddfbench_key (the config hash), family, model, shape, strategy, seed, status,
             mlflow.source.git.commit, ddfbench_finished
  metrics    every finite number of the record's metrics and cost, under its own name
             (chamfer_l2, fscore.0.01, storage_bytes, fit_s, ...)
  history    probe.<name> (probe.chamfer_l2, probe.fscore.0.01, probe.fit_s, probe.step): the fit's
             accuracy probes; MLflow step = probe index (0, 1, ...: log-spaced over the budget), and
             each point's timestamp = run start + fit time, so a chart's "relative time" axis, or
             probe.fit_s chosen as its x axis, shows accuracy against fit time
  artifacts  record.json, renders/*.png, reconstruction.ply
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import logging
import math
import os
import re
import sys
from typing import Any, Iterator, Mapping

KEY_TAG = "ddfbench_key"
FINISHED_TAG = "ddfbench_finished"
DB_NAME = "mlflow.db"
ARTIFACTS_DIR = "mlartifacts"
_MAX_PARAM_CHARS = 6000  # MLflow's limit on a param value
_BAD_NAME_CHARS = re.compile(r"[^\w.\- /]")


def default_uri(out_dir: str) -> str:
    """The embedded store: a SQLite database in the output folder."""
    return f"sqlite:///{os.path.abspath(os.path.join(out_dir, DB_NAME))}"


def metric_name(name: str) -> str:
    """A name MLflow accepts: characters outside [alnum _ . - space /] become "." (fscore@0.01 → fscore.0.01)."""
    return _BAD_NAME_CHARS.sub(".", str(name))


def flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """{"a": {"b": 1}, "c": [1, 2]} → {"a.b": 1, "c": [1, 2]} (lists stay leaves)."""
    flat: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            flat.update(flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def _number(value: Any) -> float | None:
    """A finite float for numbers and bools; None for anything else (strings, None, inf, nan)."""
    if isinstance(value, (bool, int, float)) and math.isfinite(float(value)):
        return float(value)
    return None


def record_metrics(record: Mapping[str, Any]) -> dict[str, float]:
    """Every finite number of record["metrics"] and record["cost"], flattened, under MLflow-safe names."""
    flat = {**flatten(record.get("metrics") or {}), **flatten(record.get("cost") or {})}
    return {metric_name(k): v for k, raw in flat.items() if (v := _number(raw)) is not None}


def probe_history(record: Mapping[str, Any]) -> list[tuple[str, float, int, int]]:
    """(name, value, step = probe index, fit time in ms) for every number of every accuracy probe.

    Names: probe.chamfer_l2, probe.fscore.0.01, ..., probe.step (training step), probe.fit_s."""
    out = []
    for index, probe in enumerate((record.get("fit") or {}).get("probes") or []):
        fit_ms = int(round(1000 * float(probe.get("seconds", 0.0))))
        for key, raw in probe.items():
            if (v := _number(raw)) is not None:
                out.append((f"probe.{'fit_s' if key == 'seconds' else metric_name(key)}", v, index, fit_ms))
    return out


def record_tags(record: Mapping[str, Any]) -> dict[str, str]:
    """Tags to filter runs by: the config hash, family, model, shape, strategy, seed, status, git SHA."""
    config = record.get("config") or {}
    sampling = record.get("sampling") or {}
    tags = {
        KEY_TAG: record.get("key"), FINISHED_TAG: record.get("finished"),
        "family": record.get("family"), "model": record.get("model"),
        "shape": (record.get("shape") or {}).get("name"),
        "strategy": sampling.get("strategy", sampling.get("name")),
        "seed": config.get("seed"), "status": record.get("status"),
        "mlflow.source.git.commit": (record.get("env") or {}).get("git_sha"),
        "mlflow.runName": f"{record.get('model')} {(record.get('shape') or {}).get('name')} "
                          f"seed {config.get('seed')}",
    }
    if record.get("error"):
        tags["error"] = str(record["error"])[:_MAX_PARAM_CHARS]
    return {k: str(v) for k, v in tags.items() if v is not None}


def record_params(record: Mapping[str, Any]) -> dict[str, str]:
    """The record's semantic config flattened, values as text (cut to MLflow's 6000 characters)."""
    return {metric_name(k)[:250]: str(v)[:_MAX_PARAM_CHARS] for k, v in flatten(record.get("config") or {}).items()}


def _ms(iso: str | None) -> int | None:
    return int(_dt.datetime.fromisoformat(iso).timestamp() * 1000) if iso else None


def record_artifacts(record: Mapping[str, Any], run_dir: str) -> list[tuple[str, str | None]]:
    """(local file, artifact folder) pairs: record.json, the render PNGs, the extracted mesh."""
    files: list[tuple[str, str | None]] = [(os.path.join(run_dir, "record.json"), None)]
    artifacts = record.get("artifacts") or {}
    if artifacts.get("reconstruction"):
        files.append((os.path.join(run_dir, artifacts["reconstruction"]), None))
    if artifacts.get("renders"):
        renders = os.path.join(run_dir, artifacts["renders"])
        if os.path.isdir(renders):
            files += [(os.path.join(renders, f), "renders") for f in sorted(os.listdir(renders)) if f.endswith(".png")]
    return [(path, folder) for path, folder in files if os.path.isfile(path)]


@contextlib.contextmanager
def bounded_and_quiet(timeout_s: float, max_retries: int) -> Iterator[None]:
    """Bound MLflow's HTTP retries and timeout (an unreachable server fails in seconds, not minutes),
    send no usage telemetry, and keep MLflow's, alembic's and urllib3's log lines out of the run's
    output. Variables the user has set win."""
    import mlflow  # noqa: F401  (its import sets its loggers' levels, so it comes before ours)

    env = {"MLFLOW_HTTP_REQUEST_MAX_RETRIES": str(int(max_retries)),
           "MLFLOW_HTTP_REQUEST_TIMEOUT": str(max(1, int(math.ceil(timeout_s)))),
           "MLFLOW_DISABLE_TELEMETRY": "true"}
    saved_env = {k: os.environ.get(k) for k in env}
    loggers = [logging.getLogger(n) for n in ("mlflow", "alembic", "urllib3")]
    saved_levels = [lg.level for lg in loggers]
    os.environ.update({k: os.environ.get(k) or v for k, v in env.items()})  # the user's own settings win
    for lg in loggers:
        lg.setLevel(logging.ERROR)
    try:
        yield
    finally:
        for k, v in saved_env.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        for lg, level in zip(loggers, saved_levels):
            lg.setLevel(level)


def _experiment_id(client: Any, name: str, uri: str) -> str:
    """The MLflow experiment `name`, created where missing (a SQLite store keeps artifacts beside the db)."""
    found = client.get_experiment_by_name(name)
    if found is not None:
        return found.experiment_id
    location = None
    if uri.startswith("sqlite:///"):
        from pathlib import Path

        location = Path(uri[len("sqlite:///"):]).parent.joinpath(ARTIFACTS_DIR).as_uri()
    return client.create_experiment(name, artifact_location=location)


def log_record(record: Mapping[str, Any], run_dir: str, uri: str, experiment: str | None = None) -> str | None:
    """Log one record as one MLflow run; return its run id, or None where this record is already logged.

    Raises whatever MLflow raises (track() turns that into a warning)."""
    from mlflow import MlflowClient
    from mlflow.entities import Metric, Param, RunTag

    client = MlflowClient(tracking_uri=uri)
    exp_id = _experiment_id(client, experiment or str(record.get("experiment", "single")), uri)
    tags = record_tags(record)
    query = f"tags.{KEY_TAG} = '{tags[KEY_TAG]}' and tags.{FINISHED_TAG} = '{tags.get(FINISHED_TAG, '')}'"
    if client.search_runs([exp_id], filter_string=query, max_results=1):
        return None
    run = client.create_run(exp_id, start_time=_ms(record.get("started")), tags=tags)
    run_id = run.info.run_id
    start, end = run.info.start_time, _ms(record.get("finished")) or run.info.start_time
    metrics = [Metric(k, v, end, 0) for k, v in record_metrics(record).items()]
    metrics += [Metric(k, v, start + fit_ms, index) for k, v, index, fit_ms in probe_history(record)]
    params = [Param(k, v) for k, v in record_params(record).items()]
    client.log_batch(run_id, metrics=metrics, params=params, tags=[RunTag(k, v) for k, v in tags.items()])
    for path, folder in record_artifacts(record, run_dir):
        client.log_artifact(run_id, path, folder)
    client.set_terminated(run_id, "FINISHED" if record.get("status") == "ok" else "FAILED", end_time=end)
    return run_id


def _one_line(exc: BaseException) -> str:
    lines = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {lines[0] if lines else ''}"[:300]


def track(record: Mapping[str, Any], run_dir: str, tracking: Mapping[str, Any] | None, out_dir: str) -> str | None:
    """Log `record` where the `tracking` config group says (backend none | mlflow); never raises.

    Returns the MLflow run id, or None (tracking off, already logged, or failed with one warning line)."""
    tracking = dict(tracking or {})
    if str(tracking.get("backend", "none")) != "mlflow":
        return None
    uri = str(tracking.get("uri") or default_uri(out_dir))
    try:
        with bounded_and_quiet(float(tracking.get("timeout_s", 10)), int(tracking.get("max_retries", 0))):
            return log_record(record, run_dir, uri, tracking.get("experiment"))
    except Exception as exc:  # tracking is an extra: the record on disk is what counts
        hint = " (pip install -e \".[tracking]\")" if isinstance(exc, ImportError) else ""
        print(f"ddfbench: warning: MLflow tracking to {uri} failed, record kept at "
              f"{os.path.join(run_dir, 'record.json')} ({_one_line(exc)}){hint}", file=sys.stderr, flush=True)
        return None
