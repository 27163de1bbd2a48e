"""Sweep progress: one `[n/N] ... eta` line per finished job under the basic and the joblib launcher."""

import os
import re
import subprocess
import sys

import pytest

from ddfbench.progress import claim_number, clock, progress_line, sweep_size

# Two cheap deterministic jobs (cube, mesh families, no renders); `-m` makes it a multirun.
SWEEP = ["-m", "shape=cube", "model=mesh,mesh_lod500", "eval=smoke", "scene=none", "sampling=random",
         "sampling.n_samples=2000", "experiment_name=progress", "threads=1", "quiet=true"]
LINE = re.compile(r"^\[(\d+)/(\d+)\] (\S+) cube (ok|skipped)  chamfer \S+e-3  fit \S+ s  elapsed \d+:\d\d  eta \d+:\d\d$")


def sweep(out_dir, *extra):
    out = subprocess.run([sys.executable, "-m", "ddfbench", *SWEEP, f"out_dir={out_dir}", *extra],
                         capture_output=True, text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"), timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return [m.groups() for m in map(LINE.match, out.stdout.splitlines()) if m]


@pytest.mark.parametrize("launcher", [[], ["hydra/launcher=local_parallel", "hydra.launcher.n_jobs=2"]],
                         ids=["basic", "joblib"])
def test_each_finished_job_prints_one_numbered_line(tmp_path, launcher):
    lines = sweep(tmp_path, *launcher)
    assert sorted(int(n) for n, *_ in lines) == [1, 2] and {t for _, t, *_ in lines} == {"2"}
    assert sorted(model for _, _, model, _ in lines) == ["mesh", "mesh_lod500"]
    assert {status for *_, status in lines} == {"ok"}
    again = sweep(tmp_path, *launcher)  # resumed: the ok records are skipped and still counted
    assert sorted(int(n) for n, *_ in again) == [1, 2] and {status for *_, status in again} == {"skipped"}


def test_sweep_size_follows_the_command_line_over_the_experiment_file():
    params = {"model": "ddf,mesh,grid_sdf", "shape": "bunny,cow", "seed": "0"}
    assert sweep_size(params, []) == 6
    assert sweep_size(params, ["model=ddf,mesh", "seed=0,1,2", "+experiment=x"]) == 12
    assert sweep_size({}, ["a=1,2", "b=3"]) == 2


def test_numbers_are_claimed_once_each_and_times_read_as_clocks(tmp_path):
    claimed = [claim_number(str(tmp_path)) for _ in range(3)]
    (tmp_path / "5").touch()  # a number taken by another process is skipped
    claimed += [claim_number(str(tmp_path)) for _ in range(2)]
    assert claimed == [1, 2, 3, 4, 6]
    assert (clock(7.9), clock(490), clock(3725)) == ("0:08", "8:10", "1:02:05")
    assert progress_line(12, 32, "ddf bunny ok", 490) == "[12/32] ddf bunny ok  elapsed 8:10  eta 13:37"
