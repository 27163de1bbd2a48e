"""A local_parallel worker whose sweep is killed stops within seconds instead of computing on as an orphan."""

import os
import signal
import subprocess
import sys
import time

import pytest

from ddfbench.run.worker_guard import watch_launcher

SWEEP = """
import multiprocessing, sys, time
from ddfbench.run.worker_guard import watch_launcher

def job(out):
    with open(out, "w") as fh:
        fh.write(f"{multiprocessing.current_process().pid} {watch_launcher(poll_s=0.1)}")
    time.sleep(60)  # a long fit

if __name__ == "__main__":
    multiprocessing.set_start_method("fork")
    for name, out in zip(sys.argv[1::2], sys.argv[2::2]):
        multiprocessing.Process(target=job, args=(out,), name=name).start()
    time.sleep(60)
"""


def alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return open(f"/proc/{pid}/stat").read().split()[2] != "Z" if os.path.exists(f"/proc/{pid}/stat") else True


def test_a_worker_stops_when_its_sweep_is_killed_and_another_process_does_not(tmp_path):
    worker, other = tmp_path / "worker", tmp_path / "other"
    sweep = subprocess.Popen([sys.executable, "-c", SWEEP, "LokyProcess-1", str(worker), "Process-9", str(other)])
    deadline = time.time() + 60
    while not (worker.exists() and other.exists() and worker.read_text() and other.read_text()):
        assert time.time() < deadline and sweep.poll() is None
        time.sleep(0.05)
    (w_pid, w_watched), (o_pid, o_watched) = (p.read_text().split() for p in (worker, other))
    assert (w_watched, o_watched) == ("True", "False")
    sweep.send_signal(signal.SIGKILL)  # the sweep dies; its children are re-parented
    sweep.wait()
    deadline = time.time() + 10
    while alive(int(w_pid)) and time.time() < deadline:
        time.sleep(0.05)
    try:
        assert not alive(int(w_pid))  # the watched worker ended (it polls every 0.1 s)
        assert alive(int(o_pid))  # an unwatched process computes on: what every worker did before
    finally:
        for pid in (int(w_pid), int(o_pid)):
            if alive(pid):
                os.kill(pid, signal.SIGKILL)


def test_a_process_that_is_no_worker_is_not_watched():
    assert watch_launcher(worker_prefix="LokyProcess") is False  # pytest's own process: MainProcess


@pytest.mark.slow
def test_killing_a_local_parallel_sweep_stops_its_workers(tmp_path):
    cmd = [sys.executable, "-m", "ddfbench", "-m", "model=neural_sdf", "shape=sphere", "seed=0,1", "eval=smoke",
           "scene=none", "sampling=random", "sampling.n_samples=2000", "train.budget=steps", "train.max_steps=10000000",
           "train.max_seconds=600", "threads=1", "quiet=true", "hydra/launcher=local_parallel",
           "hydra.launcher.n_jobs=2", f"out_dir={tmp_path}", f"hydra.sweep.dir={tmp_path / 'sweep'}"]
    sweep = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    workers, deadline = [], time.time() + 120
    while len(workers) < 2:  # both jobs fitting: each has written its run folder's GT mesh
        assert sweep.poll() is None and time.time() < deadline, "the sweep did not start two jobs"
        time.sleep(0.2)
        children = subprocess.run(["pgrep", "-P", str(sweep.pid)], capture_output=True, text=True).stdout.split()
        workers = [int(p) for p in children] if len(list(tmp_path.glob("*/*/gt_mesh.ply"))) >= 2 else []
    sweep.send_signal(signal.SIGTERM)
    sweep.wait()
    deadline = time.time() + 15
    while any(alive(p) for p in workers) and time.time() < deadline:
        time.sleep(0.2)
    left = [p for p in workers if alive(p)]
    for p in left:
        os.kill(p, signal.SIGKILL)
    assert not left, "workers of a killed sweep computed on"
    assert not list(tmp_path.glob("*/*/record.json"))  # stopped mid-fit: no record, none half written
