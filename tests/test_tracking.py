"""MLflow tracking against a real SQLite store in a temporary folder (no mocks)."""

import datetime
import logging
import os
import socket

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from ddfbench.core.plugins import CONF_DIR
from ddfbench.report.export_mlflow import export
from ddfbench.run import runner, runs
from ddfbench.run.tracking import KEY_TAG, default_uri, log_record

mlflow = pytest.importorskip("mlflow", reason='the tracking extra is not installed (pip install -e ".[tracking]")')


def _cfg(out_dir, *overrides):
    with initialize_config_dir(CONF_DIR, version_base="1.3"):
        cfg = compose("config", overrides=["shape=sphere", "eval.n_points=2000", "eval.mesh_resolution=24",
                                           f"out_dir={out_dir}", "threads=1", *overrides])
    return OmegaConf.to_container(cfg, resolve=True)


def _runs(uri, experiment="single"):
    client = mlflow.MlflowClient(uri)
    exp = client.get_experiment_by_name(experiment)
    return [] if exp is None else client.search_runs([exp.experiment_id]), client


def test_mesh_run_is_logged_with_tags_metrics_and_artifacts(tmp_path):
    rec = runner.run(_cfg(tmp_path, "model=mesh", "tracking=mlflow", "scene.width=16", "scene.height=16"))
    assert rec["status"] == "ok"
    found, client = _runs(default_uri(str(tmp_path)))
    assert len(found) == 1
    run = found[0]
    assert run.data.tags[KEY_TAG] == rec["key"]
    assert run.data.tags["family"] == "mesh" and run.data.tags["shape"] == "sphere"
    assert run.data.metrics["chamfer_l2"] == pytest.approx(rec["metrics"]["chamfer_l2"])
    assert run.data.metrics["storage_bytes"] == rec["cost"]["storage_bytes"]
    assert run.data.params["model.family"] == "mesh"
    started, finished = (datetime.datetime.fromisoformat(rec[k]).timestamp() * 1000 for k in ("started", "finished"))
    assert (run.info.start_time, run.info.end_time) == (started, finished)  # the run's own times, not logging time
    assert run.info.artifact_uri.startswith(f"file://{tmp_path}/mlartifacts/")  # beside the store, not ./mlruns
    top = {a.path for a in client.list_artifacts(run.info.run_id)}
    assert {"record.json", "renders"} <= top
    assert any(a.path.endswith(".png") for a in client.list_artifacts(run.info.run_id, "renders"))


def test_learned_run_has_a_probe_history_over_fit_time(tmp_path):
    rec = runner.run(_cfg(tmp_path, "model=neural_sdf", "model.width=16", "model.depth=2", "train.max_steps=60",
                          "train.max_seconds=30", "train.n_probes=5", "train.probe_points=500", "tracking=mlflow",
                          "scene=none"))
    assert rec["status"] == "ok"
    found, client = _runs(default_uri(str(tmp_path)))
    history = sorted(client.get_metric_history(found[0].info.run_id, "probe_chamfer_l2"), key=lambda m: m.step)
    assert len(history) == len(rec["fit"]["probes"]) >= 5
    assert [m.step for m in history] == list(range(len(history)))
    fit_ms = [m.timestamp - history[0].timestamp for m in history]  # the timestamps carry the fit time
    first = round(1000 * rec["fit"]["probes"][0]["seconds"])
    assert fit_ms[-1] == round(1000 * rec["fit"]["probes"][-1]["seconds"]) - first


def test_resumed_run_is_not_logged_twice(tmp_path):
    cfg = _cfg(tmp_path, "model=mesh", "tracking=mlflow", "scene=none")
    first = runner.run(cfg)
    second = runner.run(cfg)  # skipped: an ok record exists
    assert first["key"] == second["key"]
    found, _ = _runs(default_uri(str(tmp_path)))
    assert len(found) == 1


def _closed_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_unreachable_server_leaves_the_run_ok_with_one_warning(tmp_path, caplog):
    uri = f"http://127.0.0.1:{_closed_port()}"
    with caplog.at_level(logging.WARNING):
        rec = runner.run(_cfg(tmp_path, "model=mesh", "tracking=mlflow", f"tracking.uri={uri}", "scene=none"))
    assert rec["status"] == "ok"
    assert runs.is_done(runs.record_path(str(tmp_path), "single", rec["key"]))
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING and r.name == "ddfbench.run.tracking"]
    assert len(warnings) == 1 and uri in warnings[0].getMessage()


def test_tracking_does_not_change_the_record_key(tmp_path):
    assert runs.config_key(_cfg(tmp_path, "model=mesh")) == runs.config_key(_cfg(tmp_path, "model=mesh", "tracking=mlflow"))


def test_backfill_logs_every_record_once(tmp_path):
    for model in ("mesh", "grid_sdf"):
        runner.run(_cfg(tmp_path, f"model={model}", "model.resolution=24" if model == "grid_sdf" else "model.faces=0",
                        "scene=none"))
    uri = default_uri(str(tmp_path / "elsewhere"))
    os.makedirs(tmp_path / "elsewhere")
    assert export(str(tmp_path / "single"), uri) == (2, 0)
    assert export(str(tmp_path / "single"), uri) == (0, 2)
    found, _ = _runs(uri)
    assert sorted(r.data.tags["family"] for r in found) == ["grid_sdf", "mesh"]


def test_failed_record_is_logged_as_failed(tmp_path):
    record = {"key": "abc", "status": "failed", "error": "fit of x failed: NaN loss", "experiment": "e",
              "family": "ddf", "model": "ddf", "shape": {"name": "bunny"}, "config": {"seed": 0}, "metrics": {},
              "cost": {"fit_s": 1.5}, "artifacts": {}}
    runs.write_json_atomic(str(tmp_path / "r" / "record.json"), record)
    uri = default_uri(str(tmp_path))
    assert log_record(uri, record, str(tmp_path / "r")) is not None
    found, _ = _runs(uri, "e")
    assert found[0].info.status == "FAILED" and found[0].data.tags["error"].startswith("fit of x failed")


def test_a_run_whose_artifact_is_gone_is_one_line_and_logged_whole_once_it_is_back(tmp_path, capsys):
    """A missing reconstruction.ply stops the backfill with one line; the run logged in part is removed, so that the
    next backfill (the file restored) logs it whole instead of counting it as already there."""
    from ddfbench.report.export_mlflow import main as export_main

    rec = runner.run(_cfg(tmp_path, "model=mesh", "model.faces=0", "scene=none"))
    ply = tmp_path / "single" / rec["key"] / rec["artifacts"]["reconstruction"]
    kept = ply.read_bytes()
    ply.unlink()
    uri = default_uri(str(tmp_path / "elsewhere"))
    os.makedirs(tmp_path / "elsewhere")
    assert export_main([str(tmp_path / "single"), "--uri", uri]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if " INFO " not in line]  # mlflow's own log lines
    assert len(err) == 1 and err[0].startswith(f"export_mlflow: {uri}: run ") and "not logged (FileNotFoundError" in err[0]
    assert _runs(uri)[0] == []
    ply.write_bytes(kept)
    assert export(str(tmp_path / "single"), uri) == (1, 0)
    (run,), _ = _runs(uri)
    assert run.info.status == "FINISHED"
    assert export_main([str(tmp_path / "single"), "--uri", "bogus://x"]) == 2  # a store MLflow does not know
    assert "export_mlflow: bogus://x: run " in capsys.readouterr().err
    (tmp_path / "none").mkdir()
    assert export_main([str(tmp_path / "none"), "--uri", uri]) == 2
    assert capsys.readouterr().err.endswith(f"export_mlflow: {tmp_path / 'none'}: no run records below it\n")
