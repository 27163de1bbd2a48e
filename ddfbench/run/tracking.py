"""Mirror run records into MLflow (optional extra `tracking`): one ddfbench run = one MLflow run.

The JSON record stays the source of truth. `track_record` is called after the record is published;
whatever goes wrong here (mlflow not installed, server down, bad URI) is one warning line and the
run stays as it is. Logging is idempotent: an MLflow run carries the record's key as the tag
`ddfbench.key`, and a record already logged with that key and status is not logged again, so a
resumed sweep or a repeated backfill makes no duplicates.

What one MLflow run holds (experiment = the ddfbench experiment name):
  params     the resolved config, flattened with dots (`model.width`, `train.max_steps`)
  tags       ddfbench.key, family, model, shape, strategy, seed, git_sha, status, error
  metrics    every number in the record's `metrics` and `cost` (`chamfer_l2`, `storage_bytes`, `fit_s`)
             and its fit summary (`fit.steps`, `fit.seconds`), flattened with dots
  history    probe_<metric> at each accuracy probe: step = probe index, timestamp = start + fit time
  artifacts  record.json, the renders' PNGs (renders/), reconstruction.ply
"""

from __future__ import annotations

import datetime
import logging
import math
import os
import re
from typing import Any, Iterator, Mapping

from ddfbench.run.runs import RECORD_FILE

log = logging.getLogger(__name__)

KEY_TAG = "ddfbench.key"
_BATCH = 100  # MLflow's per-request limit on params (metrics and tags allow more)
_BAD_NAME = re.compile(r"[^0-9A-Za-z_\-. /]")


def default_uri(out_dir: str) -> str:
    """The embedded store: a SQLite database in the output folder."""
    return f"sqlite:///{os.path.abspath(os.path.join(out_dir, 'mlflow.db'))}"


def tracking_uri(tracking_cfg: Mapping[str, Any] | None, out_dir: str) -> str | None:
    """The MLflow URI a run logs to, or None where tracking is off (`tracking=none`)."""
    cfg = dict(tracking_cfg or {})
    if str(cfg.get("backend", "none")) != "mlflow":
        return None
    return str(cfg.get("uri") or default_uri(out_dir))


def _name(key: str) -> str:
    """An MLflow-legal metric/param name (letters, digits, `_-. /`)."""
    return _BAD_NAME.sub("_", key.replace("@", "_at_"))


def flatten(tree: Any, prefix: str = "") -> Iterator[tuple[str, Any]]:
    """(dotted key, leaf) pairs of a nested dict; lists stay leaves."""
    if isinstance(tree, Mapping):
        for k, v in tree.items():
            yield from flatten(v, f"{prefix}.{k}" if prefix else str(k))
    else:
        yield prefix, tree


def _number(value: Any) -> float | None:
    """A finite float, or None for what MLflow cannot hold as a metric (strings, lists, NaN, inf)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def record_metrics(record: Mapping[str, Any]) -> dict[str, float]:
    """Every finite number of the record's metrics, cost and fit summary, by flattened name."""
    out: dict[str, float] = {}
    fit = {k: record.get("fit", {}).get(k) for k in ("steps", "seconds", "epochs")}
    for section, tree in (("", record.get("metrics", {})), ("", record.get("cost", {})), ("fit.", fit)):
        for key, value in flatten(tree):
            if (num := _number(value)) is not None:
                out[_name(section + key)] = num
    return out


def record_tags(record: Mapping[str, Any]) -> dict[str, str]:
    """The tags a run is filtered by in the MLflow UI."""
    cfg = record.get("config", {})
    tags = {
        KEY_TAG: record.get("key"), "family": record.get("family"), "model": record.get("model"),
        "shape": (record.get("shape") or {}).get("name"), "strategy": (record.get("sampling") or {}).get("strategy"),
        "seed": cfg.get("seed"), "git_sha": (record.get("env") or {}).get("git_sha"),
        "status": record.get("status"), "error": record.get("error"),
        "mlflow.runName": f"{record.get('model')} {(record.get('shape') or {}).get('name')} seed {cfg.get('seed')}",
    }
    return {k: str(v)[:5000] for k, v in tags.items() if v is not None}


def _probe_history(record: Mapping[str, Any]) -> list[tuple[str, float, int, int]]:
    """(metric name, value, step = probe index, fit time in ms) of every accuracy probe of the fit.

    The probe index keeps every point (MLflow merges points of equal step, time and value); the fit
    time goes into the point's timestamp, so MLflow's "relative time" axis is the fit time.
    """
    out = []
    for index, probe in enumerate((record.get("fit") or {}).get("probes", [])):
        fit_ms = int(round(1000 * float(probe.get("seconds", 0.0))))
        for key, value in probe.items():
            if key not in ("step", "seconds") and (num := _number(value)) is not None:
                out.append((_name(f"probe_{key}"), num, index, fit_ms))
    return out


def _epoch_ms(stamp: Any) -> int | None:
    """An ISO-8601 time of the record (started, finished) in ms since the epoch, or None."""
    try:
        return int(datetime.datetime.fromisoformat(str(stamp)).timestamp() * 1000)
    except ValueError:
        return None


def _logged_run(client: Any, experiment_id: str, record: Mapping[str, Any]) -> bool:
    """True where an MLflow run with this record's key and status is already in the experiment."""
    found = client.search_runs([experiment_id], filter_string=f"tags.`{KEY_TAG}` = '{record.get('key')}'",
                               max_results=5)
    return any(r.data.tags.get("status") == record.get("status") for r in found)


def artifact_root(uri: str) -> str | None:
    """Where a SQLite store keeps its artifacts: `mlartifacts/` beside the database (MLflow's own
    default is ./mlruns in the working directory); None for a server, which decides itself."""
    if not uri.startswith("sqlite:///"):
        return None
    return "file://" + os.path.join(os.path.dirname(os.path.abspath(uri[len("sqlite:///"):])), "mlartifacts")


def _experiment_id(client: Any, uri: str, name: str) -> str:
    exp = client.get_experiment_by_name(name)
    return exp.experiment_id if exp is not None else client.create_experiment(name, artifact_location=artifact_root(uri))


def _artifacts(client: Any, run_id: str, run_dir: str, record: Mapping[str, Any]) -> None:
    client.log_artifact(run_id, os.path.join(run_dir, RECORD_FILE))
    arts = record.get("artifacts") or {}
    renders = os.path.join(run_dir, str(arts.get("renders") or "renders"))
    if arts.get("renders") and os.path.isdir(renders):
        for name in sorted(os.listdir(renders)):
            if name.endswith(".png"):
                client.log_artifact(run_id, os.path.join(renders, name), artifact_path="renders")
    if arts.get("reconstruction"):
        client.log_artifact(run_id, os.path.join(run_dir, str(arts["reconstruction"])))


def log_record(uri: str, record: Mapping[str, Any], run_dir: str) -> str | None:
    """Log one published record as an MLflow run; return its run id, or None if it was already there.

    Raises whatever mlflow raises: callers that must not fail use `track_record`.
    """
    os.environ.setdefault("MLFLOW_HTTP_REQUEST_MAX_RETRIES", "0")  # a dead server fails fast, not in minutes
    os.environ.setdefault("MLFLOW_HTTP_REQUEST_TIMEOUT", "10")
    from mlflow.entities import Metric, Param
    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri=uri)
    experiment_id = _experiment_id(client, uri, str(record.get("experiment", "single")))
    if _logged_run(client, experiment_id, record):
        return None
    run = client.create_run(experiment_id, start_time=_epoch_ms(record.get("started")), tags=record_tags(record))
    run_id = run.info.run_id
    try:
        params = [Param(_name(k), str(v)[:6000]) for k, v in flatten(record.get("config", {}))]
        for i in range(0, len(params), _BATCH):
            client.log_batch(run_id, params=params[i:i + _BATCH])
        now = run.info.start_time
        metrics = [Metric(k, v, now, 0) for k, v in record_metrics(record).items()]
        metrics += [Metric(k, v, now + fit_ms, index) for k, v, index, fit_ms in _probe_history(record)]
        for i in range(0, len(metrics), 1000):
            client.log_batch(run_id, metrics=metrics[i:i + 1000])
        _artifacts(client, run_id, run_dir, record)
        client.set_terminated(run_id, status="FINISHED" if record.get("status") == "ok" else "FAILED",
                              end_time=_epoch_ms(record.get("finished")))
    except BaseException:  # a run logged in part is not "already there": it goes, and the next export logs it whole
        client.delete_run(run_id)
        raise
    return run_id


def track_record(tracking_cfg: Mapping[str, Any] | None, out_dir: str, record: Mapping[str, Any],
                 run_dir: str) -> str | None:
    """Log the record where tracking is on; any failure is one warning line and returns None."""
    uri = tracking_uri(tracking_cfg, out_dir)
    if uri is None:
        return None
    try:
        return log_record(uri, record, run_dir)
    except Exception as exc:  # tracking never fails or loses a run
        first = (str(exc).strip().splitlines() or [""])[0][:300]
        log.warning("tracking: run %s not logged to %s: %s: %s", record.get("key"), uri, type(exc).__name__, first)
        return None
