"""MLflow tracking against a real SQLite store in a temp folder: what a run logs, an unreachable
server (the run stays ok, one warning line), a resumed sweep (no duplicate MLflow runs), backfill."""

import os
import socket
import subprocess
import sys

import pytest

mlflow = pytest.importorskip("mlflow")

from ddfbench import tracking  # noqa: E402
from ddfbench.report.export_mlflow import main as export_main  # noqa: E402
from ddfbench.runs import find_records  # noqa: E402

# Cheap deterministic runs (cube, mesh families) with one tiny depth render, so there are PNGs to log.
SMALL = ["shape=cube", "eval=smoke", "sampling=random", "sampling.n_samples=2000", "scene=depth", "scene.width=8",
         "scene.height=8", "scene.cameras.n=1", "scene.timing.repeats=1", "scene.timing.warmup=0",
         "experiment_name=trk", "threads=1", "quiet=true"]


def ddfbench(out_dir, *args, multirun=False):
    flags = ["-m"] if multirun else []
    return subprocess.run([sys.executable, "-m", "ddfbench", *flags, *SMALL, f"out_dir={out_dir}", *args],
                          capture_output=True, text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"), timeout=600)


def mlflow_runs(uri, experiment="trk"):
    client = mlflow.MlflowClient(uri)
    exp = client.get_experiment_by_name(experiment)
    return client, (client.search_runs([exp.experiment_id]) if exp else [])


def test_sweep_logs_each_run_once_even_when_resumed(tmp_path):
    out = ddfbench(tmp_path, "model=mesh,mesh_lod500", "tracking=mlflow", multirun=True)
    assert out.returncode == 0, out.stderr[-3000:]
    assert "warning" not in out.stderr.lower()
    uri = f"sqlite:///{tmp_path}/mlflow.db"
    client, runs = mlflow_runs(uri)
    assert sorted(r.data.tags["model"] for r in runs) == ["mesh", "mesh_lod500"]
    keys = {r["key"]: r for r in find_records(str(tmp_path / "trk"))}
    for run in runs:
        rec = keys[run.data.tags[tracking.KEY_TAG]]
        assert run.data.tags["family"] == "mesh" and run.data.tags["shape"] == "cube"
        assert run.data.tags["strategy"] == "random" and run.data.tags["seed"] == "0"
        assert run.data.metrics["chamfer_l2"] == pytest.approx(rec["metrics"]["chamfer_l2"])
        assert run.data.metrics["storage_bytes"] == rec["cost"]["storage_bytes"]
        assert run.data.metrics["fscore.0.01"] == pytest.approx(rec["metrics"]["fscore"]["0.01"])
        assert run.data.params["sampling.n_samples"] == "2000"
        top = {a.path for a in client.list_artifacts(run.info.run_id)}
        assert {"record.json", "reconstruction.ply", "renders"} <= top
        assert {a.path for a in client.list_artifacts(run.info.run_id, "renders")} == {
            "renders/cam0_depth.png", "renders/cam0_mask.png"}
    again = ddfbench(tmp_path, "model=mesh,mesh_lod500", "tracking=mlflow", multirun=True)  # resumed: both skipped
    assert again.returncode == 0, again.stderr[-3000:]
    assert sorted(r.info.run_id for r in mlflow_runs(uri)[1]) == sorted(r.info.run_id for r in runs)

    backfill_uri = f"sqlite:///{tmp_path}/backfill.db"  # backfill the same records elsewhere, twice
    assert export_main([str(tmp_path / "trk"), "--uri", backfill_uri]) == 0
    assert export_main([str(tmp_path / "trk"), "--uri", backfill_uri]) == 0
    _, backfilled = mlflow_runs(backfill_uri)
    assert sorted(r.data.tags[tracking.KEY_TAG] for r in backfilled) == sorted(keys)


def test_unreachable_server_is_one_warning_and_the_run_stays_ok(tmp_path):
    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = ddfbench(tmp_path, "model=mesh", "tracking=mlflow", f"tracking.uri=http://127.0.0.1:{port}")
    assert out.returncode == 0, out.stderr[-3000:]
    (rec,) = find_records(str(tmp_path))
    assert rec["status"] == "ok"
    warnings = [line for line in out.stderr.splitlines() if line.strip()]
    assert len(warnings) == 1 and f"127.0.0.1:{port}" in warnings[0] and "record kept" in warnings[0], out.stderr


def test_probes_become_a_metric_history_over_fit_time(tmp_path):
    seconds = [0.1, 0.3, 0.9, 2.7, 8.1]
    record = {"key": "0123456789abcdef", "experiment": "trk", "status": "ok", "family": "ddf", "model": "ddf",
              "shape": {"name": "bone"}, "sampling": {"strategy": "surface"}, "config": {"seed": 0},
              "started": "2026-01-01T00:00:00+00:00", "finished": "2026-01-01T00:01:00+00:00",
              "metrics": {"chamfer_l2": 3e-4, "fscore": {"0.01": 0.6}, "empty_reconstruction": False},
              "cost": {"fit_s": 60.0, "render_warm_s": "inf"},
              "fit": {"probes": [{"step": 10 * i, "seconds": s, "chamfer_l2": 1e-3 / (i + 1), "fscore@0.01": 0.1 * i}
                                 for i, s in enumerate(seconds)]}}
    uri = f"sqlite:///{tmp_path}/mlflow.db"
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    (run_dir / "record.json").write_text("{}")
    with tracking.bounded_and_quiet(10, 0):
        run_id = tracking.log_record(record, str(run_dir), uri)
        assert tracking.log_record(record, str(run_dir), uri) is None  # already there
    client = mlflow.MlflowClient(uri)
    history = sorted((m.step, m.timestamp, m.value) for m in client.get_metric_history(run_id, "probe.chamfer_l2"))
    start = client.get_run(run_id).info.start_time
    assert [step for step, _, _ in history] == [0, 1, 2, 3, 4]
    assert [t - start for _, t, _ in history] == [100, 300, 900, 2700, 8100]  # fit time in ms
    assert [v for _, _, v in history] == pytest.approx([1e-3 / (i + 1) for i in range(5)])
    fit_s = sorted((m.step, m.value) for m in client.get_metric_history(run_id, "probe.fit_s"))
    assert [v for _, v in fit_s] == pytest.approx(seconds)
    assert len(client.get_metric_history(run_id, "probe.fscore.0.01")) == 5
    metrics = client.get_run(run_id).data.metrics
    assert "render_warm_s" not in metrics and metrics["empty_reconstruction"] == 0.0  # non-finite left out
