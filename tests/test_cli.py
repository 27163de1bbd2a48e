"""End to end through the command line: single runs, resume, bad input, a sweep, the report."""

import json
import os
import subprocess
import sys

import pytest

from ddfbench.run.runs import RECORD_FIELDS, find_records

pytestmark = pytest.mark.slow  # every test here starts `python -m ddfbench` in a subprocess

SMALL = ["shape=cube", "model=mesh", "eval=smoke", "scene=none", "sampling=random", "sampling.n_samples=2000"]


def ddfbench(args, out_dir, module="ddfbench"):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.run([sys.executable, "-m", module, *args, f"out_dir={out_dir}"] if module == "ddfbench"
                          else [sys.executable, "-m", module, *args], capture_output=True, text=True, env=env,
                          timeout=600)


def records(root):
    return find_records(str(root))


def test_single_run_writes_a_complete_record_and_resumes(tmp_path):
    out = ddfbench(SMALL, tmp_path)
    assert out.returncode == 0, out.stderr
    (rec,) = records(tmp_path)
    assert set(RECORD_FIELDS) <= set(rec)
    assert rec["status"] == "ok" and rec["error"] is None
    assert rec["family"] == "mesh" and rec["shape"]["name"] == "cube"
    m = rec["metrics"]
    assert m["chamfer_l2"] < 2 * m["noise_floor"]["chamfer_l2"]  # the full mesh is GT: at the floor
    assert set(m["fscore"]) == {"0.001", "0.002", "0.005", "0.01", "0.02"}
    assert rec["cost"]["storage_bytes"] == os.path.getsize(os.path.join(rec["_dir"], rec["artifacts"]["model"]))
    for name in ("gt_mesh", "model", "reconstruction"):
        assert os.path.exists(os.path.normpath(os.path.join(rec["_dir"], rec["artifacts"][name]))), name
    assert "dataset" not in rec["artifacts"] and "sampling_s" not in rec["cost"]  # the mesh family draws no samples
    assert "CD-L2" in out.stdout  # the table is printed
    again = ddfbench(SMALL, tmp_path)
    assert again.returncode == 0
    (same,) = records(tmp_path)
    assert same["finished"] == rec["finished"] and same["started"] == rec["started"]  # skipped, not re-run
    forced = ddfbench(SMALL + ["force=true"], tmp_path)
    assert forced.returncode == 0
    (redone,) = records(tmp_path)
    assert redone["key"] == rec["key"] and redone["started"] >= rec["started"]
    assert json.loads(json.dumps(redone["metrics"])) == redone["metrics"]


@pytest.mark.parametrize("content,fragment", [(None, "does not exist"), (b"", "is empty"),
                                              (b"v 0 0 0\nv 1 0 0\n", "no faces")])
def test_bad_mesh_file_fails_cleanly(tmp_path, content, fragment):
    path = tmp_path / "in" / "bad.obj"
    if content is not None:
        path.parent.mkdir()
        path.write_bytes(content)
    args = [a for a in SMALL if not a.startswith("shape=")] + ["shape=file", f"shape.path={path}"]
    out = ddfbench(args, tmp_path / "res")
    assert out.returncode != 0
    last = out.stderr.strip().splitlines()[-1]
    assert str(path) in last and fragment in last
    assert (out.stdout + out.stderr).count(fragment) == 1  # one line, no table around it
    (rec,) = records(tmp_path / "res")
    assert rec["status"] == "failed" and str(path) in rec["error"]
    leftovers = [f for _, _, fs in os.walk(tmp_path / "res") for f in fs if f.endswith(".tmp")]
    assert leftovers == []


def test_sweep_goes_on_after_a_failure_and_report_renders(tmp_path):
    bad = tmp_path / "missing.obj"
    args = [a for a in SMALL if not a.startswith(("shape=", "model="))]
    out = ddfbench(["--multirun", "shape=cube,file", f"shape.path={bad}", "model=mesh,mesh_lod500",
                    "experiment_name=sweep", *args], tmp_path)
    assert out.returncode == 1  # every job ran; the sweep says how many failed
    assert out.stderr.strip().splitlines()[-1].startswith("ddfbench: 2 of 4 jobs failed (first: mesh")
    recs = records(tmp_path / "sweep")
    assert sorted(r["status"] for r in recs) == ["failed", "failed", "ok", "ok"]
    assert all(str(bad) in r["error"] for r in recs if r["status"] == "failed")
    rep = ddfbench([str(tmp_path / "sweep"), "--out", str(tmp_path / "rep")], tmp_path, module="ddfbench.report")
    assert rep.returncode == 0, rep.stderr
    md = (tmp_path / "rep" / "table.md").read_text()
    assert "mesh_lod500" in md and "failed" in md.lower()
    assert (tmp_path / "rep" / "table.tex").read_text().startswith("\\begin{tabular}")
    assert "chamfer_l2_mean" in (tmp_path / "rep" / "table.csv").read_text()
    # Hydra keeps no file of its own per job (a full disk would stop the sweep there): the records hold the configs
    jobs = [p for p in (tmp_path / ".hydra" / "sweep").glob("*/*") if p.is_dir()]
    assert len(jobs) == 4 and not [p for job in jobs for p in job.iterdir() if p.name != "ddfbench_key.txt"]


def test_a_sweep_whose_folder_cannot_be_made_stops_in_one_line_before_any_job(tmp_path):
    (tmp_path / ".hydra").write_text("")  # where the sweep's own folder goes: as unwritable as a full disk
    out = ddfbench(["--multirun", *SMALL, "seed=0,1", "experiment_name=sweep"], tmp_path)
    assert out.returncode == 1 and not (tmp_path / "sweep").exists()
    assert out.stderr.strip().splitlines()[-1].startswith(f"ddfbench: {tmp_path / '.hydra'}")
    assert out.stderr.strip().endswith("cannot be written (Not a directory); nothing ran") and "Traceback" not in out.stderr


def without_shape(args):
    return [a for a in args if not a.startswith("shape=")]


@pytest.mark.parametrize("args,named", [(SMALL + ["eval.n_points=0"], "eval.n_points=0"),
                                        (SMALL + ["seed=abc"], "seed='abc'"),
                                        (SMALL + ["train.max_seconds=nan"], "train.max_seconds=nan: must be a finite"),
                                        (without_shape(SMALL) + ["shape=file"], "shape.path is not set")])
def test_a_bad_run_value_is_a_failed_record_naming_the_key(tmp_path, args, named):
    out = ddfbench(args, tmp_path)
    assert out.returncode == 1
    last = out.stderr.strip().splitlines()[-1]
    assert named in last and "Traceback" not in out.stderr
    (rec,) = records(tmp_path)
    assert rec["status"] == "failed" and named in rec["error"]


def test_a_bad_seed_fails_its_own_run_and_the_sweep_goes_on(tmp_path):
    out = ddfbench(["--multirun", "seed=0,abc", "experiment_name=seeds", *[a for a in SMALL if a != "scene=none"],
                    "scene.width=8", "scene.height=8"], tmp_path)
    assert out.returncode == 1 and "ddfbench: 1 of 2 jobs failed" in out.stderr.strip().splitlines()[-1]
    assert sorted(r["status"] for r in records(tmp_path / "seeds")) == ["failed", "ok"]
    rep = ddfbench([str(tmp_path / "seeds"), "--out", str(tmp_path / "rep")], tmp_path, module="ddfbench.report")
    assert rep.returncode == 0, rep.stderr  # the gallery orders the ok runs by seed: the failed 'abc' is not one
    assert (tmp_path / "rep" / "gallery.png").is_file() and "seed='abc'" in (tmp_path / "rep" / "report.md").read_text()


@pytest.mark.parametrize("value,named", [("-2", "threads=-2"), ("two", "threads='two'")])
def test_bad_threads_stop_the_command_before_any_run(tmp_path, value, named):
    out = ddfbench(SMALL + [f"threads={value}"], tmp_path)
    assert out.returncode == 1 and "Traceback" not in out.stderr
    assert out.stderr.strip().splitlines() == [f"ddfbench: {named}: must be an integer >= 0"]
    assert records(tmp_path) == []


def test_a_value_the_experiment_s_level_would_replace_stops_the_command_and_capacity_null_runs_it(tmp_path):
    # the default run's first_look level sets ddf_tuned's train.max_steps to 3000: 5 steps would not be what ran
    fast = ["+experiment=default", "model=ddf_tuned", "eval=smoke", "scene=none", "threads=1"]
    out = ddfbench([*fast, "train.max_steps=5"], tmp_path)
    assert out.returncode == 1 and "Traceback" not in out.stderr
    assert out.stderr.strip().splitlines()[-1] == (
        "ddfbench: train.max_steps=5: the level capacity=first_look of experiment default sets train.max_steps to 3000 "
        "for model ddf_tuned, which would replace the value given (drop it, or run without the levels: capacity=null)")
    assert records(tmp_path) == []
    # in a sweep whose first job has no such level: the whole sweep is checked before its first job runs
    out = ddfbench(["+experiment=default", "model=mesh,neural_sdf_tuned", "shape=cube", "eval=smoke", "scene=none",
                    "threads=1", "train.max_steps=5"], tmp_path)
    assert out.returncode == 1 and "sets train.max_steps to 1000 for model neural_sdf_tuned" in out.stderr
    assert records(tmp_path) == []
    out = ddfbench([*fast, "train.max_steps=5", "capacity=null"], tmp_path)
    assert out.returncode == 0, out.stderr
    (rec,) = records(tmp_path)
    assert rec["status"] == "ok" and rec["fit"]["steps"] == 5


def test_a_package_without_its_configs_says_so_in_one_line(tmp_path):
    """A copy of the package without its conf/ (a broken install): each command names what is missing, no
    traceback."""
    import shutil

    import ddfbench

    shutil.copytree(os.path.dirname(ddfbench.__file__), tmp_path / "ddfbench",
                    ignore=shutil.ignore_patterns("__pycache__", "conf"))
    env = {**os.environ, "PYTHONPATH": str(tmp_path), "OMP_NUM_THREADS": "1"}
    line = (f"{tmp_path / 'ddfbench' / 'conf'}: no configs there: install ddfbench with them (pip install . from a "
            "checkout, whose ddfbench/conf links its conf/)")
    for args in (["ddfbench", "--help"], ["ddfbench.suite", "status", "v1"], ["ddfbench.report", str(tmp_path)]):
        done = subprocess.run([sys.executable, "-m", *args], cwd=tmp_path, env=env, capture_output=True, text=True)
        assert (done.returncode, done.stderr) == (1 if args[0] == "ddfbench" else 2, f"{args[0]}: {line}\n")
