"""Scale-out: the smoke sweep under Hydra's launchers (joblib, submitit's local executor, a local Ray instance) gives
a serial run's records; a sweep killed with SIGKILL resumes without losing or duplicating a record; --status counts done / failed / missing.
"""

import os
import re
import signal
import subprocess
import sys
import time

import pytest
import trimesh

from ddfbench.core.errors import InputError
from ddfbench.report import suite
from ddfbench.report.__main__ import main as report_main
from ddfbench.report.status import format_status, sweep_status
from ddfbench.run.launch import available_cores, job_device, job_settings, job_threads
from ddfbench.run.runs import RECORD_FIELDS, find_records

# The smoke experiment's sizes (sphere, tiny samples and metrics) on a grid of its own: two mesh models x
# two sampling strategies. The learned families stop on a wall-clock budget, so only deterministic
# families give the same metrics on every run; the grid is set here so that it does not follow the
# experiment's sweep as that grows (capacity=null: the models as their YAML gives them, not their smoke level).
SMOKE = ["+experiment=smoke", "hydra.sweeper.params=null", "model=mesh,mesh_lod500", "capacity=null",
         "sampling=random,surface"]
N_RUNS = 4
# Fields that measure time or how the work was split (not what was computed): left out of comparisons.
TIMING_KEY = re.compile(r"(_s|seconds|_threads|cache_hit|speed_vs_reference)$")
VOLATILE = ("started", "finished", "env", "_dir")


def launch(out_dir, *extra, wait=True, log=None, rc=0):
    """`python -m ddfbench <smoke sweep> out_dir=... <extra>`; waits (and expects exit code rc: 1 when a job
    failed), or returns the Popen (own session)."""
    cmd = [sys.executable, "-m", "ddfbench", *SMOKE, f"out_dir={out_dir}", *extra]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    if wait:
        out = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)
        assert out.returncode == rc, out.stderr[-3000:]
        return out
    return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True)


def by_key(out_dir):
    recs = find_records(os.path.join(str(out_dir), "smoke"))
    keys = [r["key"] for r in recs]
    assert len(keys) == len(set(keys)), "a record is duplicated"
    return {r["key"]: r for r in recs}


def comparable(rec):
    """The record minus timings, environment and paths: what the run computed."""

    def strip(value):
        if isinstance(value, dict):
            return {k: strip(v) for k, v in value.items() if not TIMING_KEY.search(k)}
        if isinstance(value, list):
            return [strip(v) for v in value]
        return value

    out = strip({k: v for k, v in rec.items() if k not in VOLATILE})
    out["overrides"] = [o for o in out["overrides"] if not o.startswith("out_dir=")]
    fit = out.get("fit") or {}
    fit["loss_curve"] = [[row[0], *row[2:]] for row in fit.get("loss_curve") or []]  # (step, seconds, loss)
    return out


def live_members(pgid):
    """Pids of processes in process group pgid that are not zombies (Linux /proc)."""
    pids = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                with open(f"/proc/{name}/stat") as fh:
                    fields = fh.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if fields[0] != "Z" and int(fields[2]) == pgid:
                pids.append(int(name))
    return pids


def file_state(path):
    st = os.stat(path)
    with open(path, "rb") as fh:
        return st.st_ino, st.st_mtime_ns, fh.read()


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """The smoke sweep run one job after another (Hydra's basic launcher): the reference records."""
    out = tmp_path_factory.mktemp("serial")
    launch(out)
    recs = by_key(out)
    assert len(recs) == N_RUNS and all(r["status"] == "ok" for r in recs.values())
    return out, recs


# --- what a launcher gives a job -----------------------------------------------------------------

@pytest.mark.parametrize("cores", [1, 2, 3, 8, 16, 64])
def test_joblib_jobs_times_threads_fill_the_cores(cores):
    for n_jobs in range(1, cores + 1):
        threads = job_threads(0, {"n_jobs": n_jobs}, cores)
        assert threads >= 1 and n_jobs * threads <= cores < n_jobs * (threads + 1)
    assert job_threads(0, {"n_jobs": -1}, cores) == 1  # one job per core
    assert job_threads(0, {"n_jobs": 2 * cores}, cores) == 1  # oversubscribed: never 0 threads


def test_reserved_cores_and_explicit_threads_win():
    assert job_threads(0, {"cpus_per_task": 4}, 16) == 4  # submitit (SLURM binds these cores)
    assert job_threads(0, {"cpus_per_task": 32}, 8) == 8  # never more than the process can run on
    assert job_threads(0, {"ray": {"remote": {"num_cpus": 3, "num_gpus": 1}}}, 16) == 3
    assert job_threads(5, {"n_jobs": 4}, 16) == 5  # threads=5 on the command line is kept
    assert job_threads(0, {"_target_": "BasicLauncher"}, 6) == 6  # one job at a time: every core
    assert job_threads(0, None, 6) == 6


def test_job_settings_take_an_environment_variable_s_digits_and_refuse_a_negative_count():
    hydra_cfg = {"launcher": {"n_jobs": 2}, "job": {"num": 0}}
    assert job_settings({"threads": "3"}, hydra_cfg)[0] == 3  # threads=${oc.env:SLURM_CPUS_PER_TASK}: a string
    assert job_settings({"threads": None}, hydra_cfg)[0] == job_threads(0, hydra_cfg["launcher"], available_cores())
    with pytest.raises(InputError, match=r"threads=-1: must be an integer >= 0"):
        job_settings({"threads": -1}, hydra_cfg)


def test_device_follows_the_visible_gpus():
    assert job_device("auto", 3, 0) == "cpu"  # the launcher hid every GPU
    assert job_device("cpu", 3, 4) == "cpu"
    assert [job_device("auto", n, 2) for n in range(4)] == ["cuda:0", "cuda:1", "cuda:0", "cuda:1"]
    assert job_device("cuda", 5, 1) == "cuda:0"  # SLURM / Ray: the task sees only its own GPU
    assert job_device("cuda:1", 0, 4) == "cuda:1"
    assert job_device("cuda", 0, 0) == "cuda"  # left for the runner to reject with a clear message


# --- launchers give the serial run's records ---------------------------------------------------

# Ray on this machine: a local instance of two CPUs, one CPU and no GPU a run, no dashboard.
RAY_LOCAL = ["hydra.launcher.ray.remote.num_gpus=0", "hydra.launcher.ray.remote.num_cpus=1",
             "+hydra.launcher.ray.init.num_cpus=2", "+hydra.launcher.ray.init.include_dashboard=false"]


def ray_can_start():
    """None when a local Ray instance starts here, else why not (the test skips, printing it; under CI it fails)."""
    code = "import ray; ray.init(num_cpus=1, include_dashboard=False); ray.shutdown()"
    try:
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        return "ray.init() did not return in 120 s"
    return None if done.returncode == 0 else (done.stderr.strip().splitlines() or ["ray.init() failed"])[-1]


@pytest.mark.parametrize("launcher", ["local_parallel", "slurm_local", "ray"])
@pytest.mark.slow
def test_launcher_records_equal_the_serial_run(serial, tmp_path, launcher):
    serial_dir, expected = serial
    if launcher == "ray" and (why := ray_can_start()):
        message = f"a local Ray instance cannot start here: {why}"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    options = [f"hydra/launcher={launcher}", *(RAY_LOCAL if launcher == "ray" else [])]
    launch(tmp_path, *options)
    got = by_key(tmp_path)
    assert set(got) == set(expected)
    for key, rec in got.items():
        assert rec["status"] == "ok", rec["error"]
        assert comparable(rec) == comparable(expected[key]), key
    cores = len(os.sched_getaffinity(0))
    # n_jobs=2; cpus_per_task=1; num_cpus=1
    threads = {"local_parallel": max(1, cores // 2), "slurm_local": 1, "ray": 1}[launcher]
    assert {r["env"]["threads"] for r in got.values()} == {threads}
    if launcher != "local_parallel":  # no GPU reserved: submitit and Ray hide every GPU, train.device=auto runs on cpu
        assert {r["env"]["device"] for r in got.values()} == {"cpu"}
    # A mesh builds from the mesh itself: no run built a dataset, none is cached.
    assert not any("dataset" in r["artifacts"] or "n_samples" in r["sampling"] for r in got.values())
    assert not os.path.exists(os.path.join(str(tmp_path), ".cache", "datasets"))
    st = sweep_status(os.path.join(str(tmp_path), "smoke"))
    assert st.complete and {j.key for j in st.done} == set(expected)
    if launcher != "local_parallel":  # submitted again (docs/usage.md): every job finds its ok record and ends at once
        states = {key: file_state(os.path.join(rec["_dir"], "record.json")) for key, rec in got.items()}
        launch(tmp_path, *options)
        assert {key: file_state(os.path.join(rec["_dir"], "record.json")) for key, rec in by_key(tmp_path).items()} == states


# --- SIGKILL part way, then re-launch ------------------------------------------------------------

@pytest.mark.slow
def test_killed_sweep_resumes_without_loss_or_duplicates(tmp_path):
    with open(tmp_path / "first.log", "w") as log:
        proc = launch(tmp_path, "hydra/launcher=local_parallel", wait=False, log=log)
        records_dir = os.path.join(str(tmp_path), "smoke")
        deadline = time.monotonic() + 240
        while not (os.path.isdir(records_dir) and find_records(records_dir)):
            assert proc.poll() is None, (tmp_path / "first.log").read_text()[-3000:]
            assert time.monotonic() < deadline, "no record appeared"
            time.sleep(0.02)
        os.killpg(proc.pid, signal.SIGKILL)  # the sweep and its workers, mid-run
        proc.wait()
    while live_members(proc.pid):  # no worker may write after the snapshot
        assert time.monotonic() < deadline, "workers outlived SIGKILL"
        time.sleep(0.05)

    before = by_key(tmp_path)
    assert 1 <= len(before) < N_RUNS
    for rec in before.values():  # either no record or a complete one
        assert rec["status"] == "ok" and set(RECORD_FIELDS) <= set(rec)
    states = {k: file_state(os.path.join(r["_dir"], "record.json")) for k, r in before.items()}
    st = sweep_status(records_dir)  # the grid from the sweep's multirun.yaml
    assert {j.key for j in st.done} == set(before) and not st.failed
    assert [j.key for j in sweep_status(records_dir, SMOKE).expected] == [j.key for j in st.expected]  # from overrides
    assert len(st.missing) == N_RUNS - len(before)
    assert not suite.sweep_ran_through(records_dir, -9, 0.0)  # cut short: no follow-up sweep starts from it

    launch(tmp_path)  # the same sweep again (serial this time: keys do not depend on the launcher)
    after = by_key(tmp_path)
    assert set(after) == {j.key for j in st.expected}  # nothing lost, nothing extra
    assert all(r["status"] == "ok" for r in after.values())
    for key, state in states.items():  # finished runs were skipped, not redone
        assert file_state(os.path.join(after[key]["_dir"], "record.json")) == state, key
    n_files = sum("record.json" in files for _, _, files in os.walk(tmp_path))
    assert n_files == N_RUNS
    assert sweep_status(records_dir).complete


# --- failed runs run again -----------------------------------------------------------------------

@pytest.mark.slow
def test_failed_runs_rerun_and_status_reports_them(tmp_path, capsys):
    mesh = tmp_path / "late.obj"
    args = ["shape.name=file", f"shape.path={mesh}", "sampling=random"]  # both models
    out = launch(tmp_path, *args, rc=1)  # every job ran, and the sweep says they failed
    assert out.stderr.strip().splitlines()[-1].startswith("ddfbench: 2 of 2 jobs failed (first: ")
    first = by_key(tmp_path)
    assert len(first) == 2 and all(r["status"] == "failed" for r in first.values())
    records_dir = os.path.join(str(tmp_path), "smoke")
    st = sweep_status(records_dir)
    assert len(st.failed) == 2 and not st.done and not st.missing
    assert {j.key for j, _ in st.failed} == set(first)
    text = format_status(records_dir, st)
    for job, error in st.failed:
        assert str(mesh) in error and "\n" not in error
        assert f"[{job.key}]  {error}" in text
    assert "done 0  failed 2  missing 0" in text
    assert suite.sweep_ran_through(records_dir, 1, 0.0)  # every job has a record, failed ones too: follow-ups may run
    # a later sweep that stopped before its first job wrote no grid of its own: its exit code decides, not this one
    assert not suite.sweep_ran_through(records_dir, 1, time.time() + 1)

    trimesh.creation.box().export(mesh)  # the cause is fixed: the same sweep runs them again, keyed on the
    launch(tmp_path, *args)                # file's contents (a new input is a new run; the failed ones stay as theirs)
    again = by_key(tmp_path)
    fixed = {key: rec for key, rec in again.items() if key not in first}
    assert set(first) < set(again) and len(fixed) == 2
    assert all(r["status"] == "ok" and r["error"] is None for r in fixed.values())
    assert sweep_status(records_dir).complete
    capsys.readouterr()
    for argv in ([records_dir, "--status"], ["--status", records_dir]):  # the folder before or after the flag
        assert report_main(argv) == 0 and "done 2  failed 0  missing 0" in capsys.readouterr().out
