"""`+experiment=tune`: search spaces read from the model YAMLs, trials drawn inside them, the objective a
job returns, and the study's report and resumption."""

import math
import subprocess
import sys

import pandas as pd
import pytest

from ddfbench.core import plugins
from ddfbench.core.errors import InputError
from ddfbench.evaluate.metric_registry import by_name, check_objective, objective_value
from ddfbench.fit import tune
from ddfbench.run.runs import find_records

optuna = pytest.importorskip("optuna", reason="the `tune` extra (hydra-optuna-sweeper) is not installed")


def test_every_learned_family_declares_a_space_and_the_paper_presets_do_not():
    tuned = set(plugins.members("model", tune.EXPERIMENT))
    assert {"ddf", "neural_sdf", "gan_sdf"} <= tuned
    assert not {"ddf_paper", "ddf_paper_lr", "mesh", "grid_sdf"} & tuned  # as written / not learned
    for model in tuned:
        assert tune.search_space(model)


@pytest.mark.parametrize("spec,message", [
    ({"model.lr": {"log": [0.0, 1.0]}}, "log needs [low, high]"),
    ({"model.lr": {"float": [1.0, 0.5]}}, "float needs [low, high]"),
    ({"model.lr": {"normal": [0, 1]}}, "kind one of log, float, int, choice"),
    ({"model.widht": {"choice": [64]}}, "not a key of the model"),
    ({"model.width": {"choice": []}}, "choice needs at least one value")])
def test_a_malformed_space_is_one_line_naming_the_file_and_entry(monkeypatch, spec, message):
    monkeypatch.setattr(plugins, "levels", lambda group, name, experiment: spec)
    with pytest.raises(InputError) as err:
        tune.search_space("ddf")
    text = str(err.value)
    assert "conf/model/ddf.yaml: experiments.tune." in text and message in text and "\n" not in text


def test_a_preset_must_hold_each_key_its_study_draws(monkeypatch):
    # ddf_tuned gives no lr_schedule (its family's YAML does): the sweeper's `model.lr_schedule=` override
    # would fail in every trial, so the space is refused up front, naming the key and the file to set it in
    monkeypatch.setattr(plugins, "levels", lambda group, name, experiment: {"model.lr_schedule": {"choice": ["cosine"]}})
    with pytest.raises(InputError) as err:
        tune.search_space("ddf_tuned")
    text = str(err.value)
    assert "conf/model/ddf_tuned.yaml: experiments.tune.model.lr_schedule" in text and "\n" not in text and "lr_schedule: 'cosine'" in text
    assert tune.search_space("ddf") == {"model.lr_schedule": ("choice", ["cosine"])}  # ddf.yaml holds it


def test_suggest_draws_every_key_inside_its_declared_range():
    from omegaconf import OmegaConf

    config = OmegaConf.create({"hydra": {"runtime": {"choices": {"model": "ddf"}}}})
    study = optuna.create_study(sampler=optuna.samplers.RandomSampler(seed=3))
    space = tune.search_space("ddf")
    for _ in range(20):
        trial = study.ask()
        tune.suggest(config, trial)
        assert set(trial.params) == set(space)
        for path, (kind, values) in space.items():
            value = trial.params[path]
            if kind == "choice":
                assert value in values
            else:
                assert values[0] <= value <= values[1]
                assert isinstance(value, int) == (kind == "int")
        study.tell(trial, 1.0)


def test_the_objective_is_the_metric_or_its_penalty():
    chamfer = by_name()["chamfer_l2"]
    ok = {"status": "ok", "metrics": {"chamfer_l2": 2.5e-5}}
    assert objective_value(ok, "chamfer_l2") == 2.5e-5
    assert objective_value({"status": "failed", "metrics": {}}, "chamfer_l2") == chamfer.penalty
    assert objective_value({"status": "ok", "metrics": {"chamfer_l2": math.nan}}, "chamfer_l2") == chamfer.penalty
    assert objective_value({"status": "ok", "metrics": {}}, "mask_iou") == -math.inf  # no penalty: its worst end
    with pytest.raises(InputError, match="objective=chamfr: not a metric"):
        objective_value(ok, "chamfr")


def test_an_objective_whose_better_end_the_study_runs_from_is_refused():
    check_objective("chamfer_l2", "minimize")
    check_objective("fscore@0.01", "maximize")
    with pytest.raises(InputError, match=r"objective=fscore@0.01: higher is better, and the study would minimize"):
        check_objective("fscore@0.01", "minimize")  # a failed trial's F of 0 would be the study's best
    with pytest.raises(InputError, match=r"objective=chamfer_l2: lower is better, and the study would maximize"):
        check_objective("chamfer_l2", "maximize")
    with pytest.raises(InputError, match="objective=steps: a setting or count"):
        check_objective("steps", "minimize")
    with pytest.raises(InputError, match="objective=steps: a setting or count"):
        objective_value({"status": "ok", "fit": {"steps": 3}}, "steps")


@pytest.mark.parametrize("study", (["+experiment=tune", "model=neural_sdf"],  # direction: minimize in its YAML
                                   ["-m", "hydra/sweeper=optuna", "model=mesh"]))  # Optuna's default, an enum
def test_a_study_refuses_a_wrong_way_objective_before_any_job(tmp_path, study):
    done = subprocess.run([sys.executable, "-m", "ddfbench", *study, "objective=fscore@0.01", f"out_dir={tmp_path}",
                           f"hydra.sweep.dir={tmp_path}/sweep"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 1
    assert done.stderr.strip().splitlines() == [
        "ddfbench: objective=fscore@0.01: higher is better, and the study would minimize it "
        "(hydra.sweeper.direction=minimize)"]
    assert not (tmp_path / "tune").exists()


def test_without_the_extra_the_tune_experiment_is_one_line(monkeypatch):
    import importlib.util

    from ddfbench import cli

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "optuna" else real(name, *a))
    with pytest.raises(InputError, match=r'^\+experiment=tune: needs the `tune` extra \(pip install -e "\.\[tune\]"\)$'):
        cli.check_extras(["+experiment=tune", "model=ddf"])
    cli.check_extras(["+experiment=smoke"])  # other experiments need no extra


@pytest.mark.slow
def test_a_study_runs_reports_and_resumes_from_its_records(tmp_path):
    from ddfbench.report.tune import rebuild, write

    cmd = [sys.executable, "-m", "ddfbench", "+experiment=tune", "model=neural_sdf", "hydra.sweeper.n_trials=3",
           "shape.name=sphere", "train.max_seconds=0.5", "eval.n_points=1000", "eval.mesh_resolution=16",
           "train.probe_points=500", "sampling.s_dr=2", "sampling.s_p=2", "threads=1", "quiet=true",
           f"out_dir={tmp_path}"]
    first = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert first.returncode == 0, first.stderr[-2000:]
    records = find_records(str(tmp_path / "tune"))
    assert len(records) == 3 and all(r["status"] == "ok" for r in records)
    drawn = {tuple(sorted(o for o in r["overrides"] if o.startswith("model."))) for r in records}
    assert len(drawn) == 3  # three different trials, each a record of its own

    again = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr[-2000:]
    assert len(find_records(str(tmp_path / "tune"))) == 3  # the seeded sampler re-proposed the same trials

    preset = subprocess.run([*cmd, "hydra.mode=RUN"], capture_output=True, text=True, timeout=600)
    assert preset.returncode == 0, preset.stderr[-2000:]  # the preset's own values at the same budget

    df = write(str(tmp_path / "tune"), str(tmp_path / "report"))
    assert list(df["kind"]) == ["trial"] * 3 + ["preset"] and list(df["trial"].dropna()) == [0, 1, 2]
    csv = pd.read_csv(tmp_path / "report" / "trials.csv")
    assert set(tune.search_space("neural_sdf")) <= set(csv.columns)
    best = (tmp_path / "report" / "best.md").read_text()
    assert "Every model: 3 trials, 0.5 s of fit each" in best
    assert f"{csv[csv['kind'] == 'trial']['objective'].min():.4g}" in best
    assert f"same budget: CD-L2 x10^3 {csv[csv['kind'] == 'preset']['objective'].iloc[0]:.4g}" in best
    assert (tmp_path / "report" / "tune.png").stat().st_size > 0
    rebuild(str(tmp_path / "report"), str(tmp_path / "rebuilt"), draw=False)  # from trials.csv and study.json alone
    for name in ("trials.csv", "trials.md", "best.md", "space.md"):
        assert (tmp_path / "rebuilt" / name).read_bytes() == (tmp_path / "report" / name).read_bytes(), name


def test_the_optuna_sweepers_default_direction_is_read_as_its_name():
    """Without `direction` in the YAML, Optuna's sweeper holds its Direction enum, whose str() is
    "Direction.minimize": the check read that as no direction and refused every such study."""
    from hydra_plugins.hydra_optuna_sweeper.config import Direction
    from omegaconf import OmegaConf

    from ddfbench.cli import sweep_direction

    assert sweep_direction(Direction.minimize) == "minimize" and sweep_direction("maximize") == "maximize"
    assert sweep_direction(OmegaConf.create({"d": [Direction.maximize]}).d) == "maximize"
