"""`python -m ddfbench +experiment=NAME --help` describes the experiment: its file's header, what it sweeps and
how many jobs the given arguments make."""

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
