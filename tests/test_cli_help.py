"""`python -m ddfbench +experiment=NAME --help` describes the experiment: its file's header, what it sweeps and
how many jobs the given arguments make; a sweep ends with one line on its failed jobs."""

import pytest

from ddfbench.cli import experiment_help


def test_an_experiments_help_gives_its_description_its_axes_and_its_job_count():
    text = experiment_help(["+experiment=default", "--help"])
    assert "fixed number of steps" in text and "@package" not in text
    assert "sweep over: model; 6 jobs with these arguments" in text
    seeds = experiment_help(["+experiment=default", "seed=0,1", "-h"])
    assert "sweep over: model, seed; 12 jobs" in seeds


def test_an_optimizing_sweep_is_described_without_a_grid():
    text = experiment_help(["+experiment=tune", "model=ddf", "--help"])
    assert "sweep: not expanded here" in text and "OptunaSweeper" in text


def test_without_an_experiment_hydra_answers():
    assert experiment_help(["model=mesh", "--help"]) is None
    assert experiment_help(["+experiment=no_such_one", "--help"]) is None


def test_a_sweep_with_failed_jobs_names_how_many_and_the_first_by_job_number(tmp_path, capsys):
    from omegaconf import OmegaConf

    from ddfbench.cli import KEY_FILE, SweepTableCallback
    from ddfbench.run import runs

    sweep, out = tmp_path / "sweep", tmp_path / "out"
    for job, status in (("10", "failed"), ("2", "failed"), ("3", "ok")):  # job 10 sorts before 2 as text
        key = f"k{job}"
        (sweep / job).mkdir(parents=True)
        (sweep / job / KEY_FILE).write_text(f"e/{key}\n")
        (out / "e" / key).mkdir(parents=True)
        runs.write_json_atomic(str(out / "e" / key / runs.RECORD_FILE), {
            "key": key, "experiment": "e", "status": status, "model": f"m{job}", "shape": {"name": "cube"},
            "error": None if status == "ok" else f"boom {job}", "metrics": {}, "cost": {}, "config": {}})
    config = OmegaConf.create({"hydra": {"sweep": {"dir": str(sweep)}}, "out_dir": str(out), "quiet": True})
    with pytest.raises(SystemExit) as stop:
        SweepTableCallback().on_multirun_end(config)
    assert stop.value.code == 1
    assert capsys.readouterr().err == "ddfbench: 2 of 3 jobs failed (first: m2 on cube: boom 2)\n"


def test_a_sweep_whose_jobs_left_no_record_exits_1_and_says_how_many(tmp_path, capsys):
    """Two jobs of three could not write their records (a read-only folder) or were killed first: the sweep
    does not end as if it had succeeded."""
    from omegaconf import OmegaConf

    from ddfbench.cli import KEY_FILE, SweepTableCallback
    from ddfbench.run import progress, runs

    sweep, out = tmp_path / "sweep", tmp_path / "out"
    progress.start_sweep(str(sweep), 3)
    (sweep / "0").mkdir()
    (sweep / "0" / KEY_FILE).write_text("e/k0\n")
    (out / "e" / "k0").mkdir(parents=True)
    runs.write_json_atomic(str(out / "e" / "k0" / runs.RECORD_FILE), {
        "key": "k0", "experiment": "e", "status": "ok", "model": "m", "shape": {"name": "cube"}, "error": None,
        "metrics": {}, "cost": {}, "config": {}})
    (sweep / "1").mkdir()
    (sweep / "1" / KEY_FILE).write_text("e/k1\n")  # its record.json was never written
    config = OmegaConf.create({"hydra": {"sweep": {"dir": str(sweep)}}, "out_dir": str(out), "quiet": True})
    with pytest.raises(SystemExit) as stop:
        SweepTableCallback().on_multirun_end(config)
    assert stop.value.code == 1
    assert capsys.readouterr().err == "ddfbench: 2 of 3 jobs failed (2 left no record)\n"


def test_the_plain_help_opens_with_what_ddfbench_runs_and_where_to_read_more():
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "ddfbench", "--help"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0
    head = done.stdout.split("== Configuration groups ==")[0]
    assert head.startswith("python -m ddfbench: one run") and "powered by Hydra" not in head
    assert "`+experiment=NAME --help`" in head and "README.md" in head


def test_the_suite_help_names_its_tiers_and_the_overrides_after_a_double_dash(capsys):
    import pytest

    from ddfbench.report.suite import load_suite, main

    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f"(v1: {', '.join(load_suite('v1'))})" in text  # the tiers the suite file has
    assert "run nothing" in text and "after `--`" in text
