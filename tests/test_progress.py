"""Sweep progress lines: job counts, a lock-protected counter, and the lines a real sweep prints."""

import multiprocessing as mp
import os
import re
import subprocess
import sys

import pytest

from ddfbench.run import progress

LINE = re.compile(r"^\[(\d+)/(\d+)\] (\S+) (\S+) (ok|failed)  .*elapsed \d+:\d\d(  eta \d+:\d\d)?$")


def test_count_jobs_is_the_product_of_the_sweep_lists():
    assert progress.count_jobs(["seed=0,1,2", "shape=bunny"], {"+experiment/capacity": "mesh,ddf", "capacity": "c1,c2"}) == 12
    assert progress.count_jobs(["model=mesh"], None) == 1
    # a command-line list replaces the experiment's list for the same key, as in Hydra's basic sweeper
    assert progress.count_jobs(["seed=0,1"], {"seed": "0,1,2,3,4"}) == 2
    assert progress.count_jobs([], {"x": "1,2"}, n_trials=24) == 24


def _finish(args):
    sweep_dir, i = args
    return progress.job_finished(sweep_dir, {"model": "mesh", "shape": {"name": "cube"}, "status": "ok"})


def test_parallel_workers_never_print_the_same_count(tmp_path):
    progress.start_sweep(str(tmp_path), 16)
    with mp.get_context("spawn").Pool(4) as pool:
        lines = pool.map(_finish, [(str(tmp_path), i) for i in range(16)])
    counts = sorted(int(LINE.match(line).group(1)) for line in lines)
    assert counts == list(range(1, 17))


def test_line_names_the_job_its_result_and_the_remaining_time():
    rec = {"model": "ddf", "shape": {"name": "bunny"}, "status": "ok", "metrics": {"chamfer_l2": 3.5e-4},
           "cost": {"fit_s": 60.2}}
    text = progress.line(12, 32, rec, 490.0)
    assert text == "[12/32] ddf bunny ok  chamfer 0.35e-3  fit 60.2 s  elapsed 8:10  eta 13:37"
    empty = dict(rec, flags=["empty_reconstruction"], metrics={"chamfer_l2": 8.64})
    assert "penalty" in progress.line(32, 32, empty, 10.0) and "eta" not in progress.line(32, 32, empty, 10.0)
    open_input = dict(rec, flags=["non_watertight_input"])  # else only the record's flags said so
    assert "open input mesh" in progress.line(32, 32, open_input, 10.0)
    assert "open input" not in text


def test_no_state_no_line(tmp_path):
    assert progress.job_finished(str(tmp_path), {"status": "ok"}) is None


@pytest.mark.slow
@pytest.mark.parametrize("launcher", ["basic", "local_parallel"])
def test_sweep_prints_one_line_per_job_with_counts(tmp_path, launcher):
    args = [sys.executable, "-m", "ddfbench", "-m", "model=mesh", "shape=sphere,cube", "scene=none",
            "eval.n_points=1000", "eval.mesh_resolution=16", f"out_dir={tmp_path}", "threads=1"]
    if launcher != "basic":
        args += [f"hydra/launcher={launcher}", "hydra.launcher.n_jobs=2"]
    env = dict(os.environ, CI="true")
    first = subprocess.run(args, capture_output=True, text=True, env=env, timeout=600)
    assert first.returncode == 0, first.stderr[-2000:]
    lines = [ln for ln in first.stdout.splitlines() if ln.startswith("[")]
    assert sorted(int(LINE.match(ln).group(1)) for ln in lines) == [1, 2]
    assert all(LINE.match(ln).group(2) == "2" for ln in lines)
    assert "#0 :" not in first.stdout + first.stderr  # CI logs hold the progress lines, not Hydra's job list
    # a resumed sweep skips both runs and still counts them as done
    second = subprocess.run(args, capture_output=True, text=True, env=env, timeout=600)
    lines = [ln for ln in second.stdout.splitlines() if ln.startswith("[")]
    assert sorted(ln.split("]")[0] for ln in lines if LINE.match(ln)) == ["[1/2", "[2/2"] and len(lines) == 2


def test_a_failed_jobs_line_carries_its_error():
    from ddfbench.run.progress import line

    rec = {"model": "ddf", "shape": {"name": "cow"}, "status": "failed", "error": "shape file /x.obj: does not exist",
           "metrics": {}, "cost": {}}
    assert line(13, 32, rec, 491.0) == "[13/32] ddf cow failed  shape file /x.obj: does not exist  elapsed 8:11  eta 11:58"
