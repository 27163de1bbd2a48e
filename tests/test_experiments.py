"""Experiment configs: each expands to the grid it documents over the registered plugins (the models
and samplers whose YAML joins it), and the smoke sweep runs end to end (a subprocess, as CI runs it)
into records and report files that all parse."""

import functools
import json
import os
import re
import subprocess
import sys

import matplotlib.image
import pandas as pd
import pytest

from ddfbench.core import plugins
from ddfbench.core.errors import InputError
from ddfbench.core.plugins import CONF_DIR
from ddfbench.models import load_family
from ddfbench.report.plots import PLOTS_BY_EXPERIMENT
from ddfbench.report.status import expected_grid
from ddfbench.run.runs import RECORD_FIELDS, find_records

FAMILIES = set(plugins.members("model", "smoke"))  # every model with a smoke level (the ddf_paper preset included)
SAMPLERS = set(plugins.members("sampling", "smoke"))


def n_members(group, experiment):
    return len(plugins.members(group, experiment))


@functools.lru_cache(maxsize=None)
def _grid(experiment, overrides):
    jobs, _ = expected_grid(os.path.join("/nonexistent", experiment), [f"+experiment={experiment}", *overrides])
    return jobs


def grid(experiment, *overrides):
    """The sweep's jobs as `--status` expands them (composed once per test session: composing is slow)."""
    return _grid(experiment, overrides)


def swept(job):
    return dict(o.split("=", 1) for o in job.swept)


LARGE = pytest.mark.slow  # composing a job's config takes ~0.2 s: grids of 80+ jobs leave the fast lane


# One seed: the seed lists are SEEDS' test below; composing each job costs ~0.2 s, so the grids expand at seed=0.
@pytest.mark.parametrize("experiment,n_jobs", [
    ("ablation", lambda: 7), pytest.param("ablation_grid", lambda: 27, marks=LARGE),
    pytest.param("sampling", lambda: 4 * n_members("sampling", "sampling"), marks=LARGE),  # levels xs s m l
    pytest.param("representations", lambda: 4 * n_members("model", "representations"), marks=LARGE),
    pytest.param("storage", lambda: 4 * n_members("model", "storage"), marks=LARGE),
    pytest.param("pareto", lambda: 4 * n_members("model", "pareto"), marks=LARGE),
    pytest.param("render_time", lambda: 3 * n_members("model", "render_time"), marks=LARGE),  # 3 image sizes
    ("smoke", lambda: n_members("model", "smoke") * n_members("sampling", "smoke"))])
def test_experiment_expands_to_its_documented_grid(experiment, n_jobs, tmp_path):
    jobs = grid(experiment, *([] if experiment == "smoke" else ["seed=0"]))
    assert len(jobs) == n_jobs()
    assert len({j.key for j in jobs}) == len(jobs)  # every job is a distinct configuration


@LARGE
def test_ablation_is_one_factor_at_a_time_and_shares_records_with_the_grid(tmp_path):
    points = set()
    for job in grid("ablation", "seed=0"):
        levels = json.loads(swept(job)["sampling"].replace("s_fc", '"s_fc"').replace("s_dr", '"s_dr"')
                            .replace("s_p", '"s_p"'))
        points.add((levels["s_fc"], levels["s_dr"], levels["s_p"]))
    expected = {(10, 10, 10)} | {tuple(v if i == k else 10 for i in range(3)) for k in range(3) for v in (20, 30)}
    assert points == expected
    assert {j.key for j in grid("ablation", "seed=0")} <= {j.key for j in grid("ablation_grid", "seed=0")}


@LARGE
def test_budget_overrides_and_seeds_change_the_grid(tmp_path):
    base = grid("sampling")
    scaled = grid("sampling", "train.max_steps=5", "seed=0,1,2,3")
    assert len(scaled) == len(base) // 3 * 4
    assert not {j.key for j in base} & {j.key for j in scaled}  # a budget is part of the record key


def test_the_built_in_plugins_join_the_documented_experiments():
    """The documented membership: these lists change only when a YAML joins or leaves."""
    assert FAMILIES == {"mesh", "grid_sdf", "ddf", "ddf_paper", "neural_sdf", "gan_sdf"}
    assert SAMPLERS == set(plugins.members("sampling", "sampling")) == {"random", "pov", "surface"}
    assert set(plugins.members("model", "default")) == {"mesh", "mesh_lod2000", "mesh_lod500", "grid_sdf",
                                                        "neural_sdf_tuned", "ddf_tuned"}
    # the capacity sweeps take the tuned presets and the papers' presets as written, not the hand-set ones
    for experiment in ("storage", "pareto"):
        assert set(plugins.members("model", experiment)) == {"mesh", "grid_sdf", "ddf_tuned", "ddf_paper",
                                                              "neural_sdf_tuned", "gan_sdf_tuned", "gan_sdf"}


def test_capacity_sweeps_cover_every_registered_model(tmp_path):
    # one seed and one level: the model axis is what is checked (each job composed with its level applied)
    for experiment, level in (("storage", "capacity=c4"), ("pareto", "capacity=c4"), ("smoke", "sampling=random")):
        families = {swept(j)["model"] for j in grid(experiment, "seed=0", level)}
        assert families == set(plugins.members("model", experiment)), experiment


def test_a_level_is_a_partial_config_merged_onto_the_job():
    base = {"experiment_name": "pareto", "capacity": "c2", "train": {"max_seconds": 45, "max_steps": 9},
            "model": plugins.plugin_yaml("model", "ddf_tuned"), "sampling": plugins.plugin_yaml("sampling", "random")}
    job = plugins.job_config(base)
    assert (job["model"]["width"], job["model"]["depth"]) == (128, 4) and "experiments" not in job["model"]
    assert job["model"]["lr"] == base["model"]["lr"]  # the preset's own values stay
    assert "experiments" not in job["sampling"] and job["train"] == base["train"]
    with pytest.raises(InputError, match="capacity=c9: model ddf has no such level for experiment pareto"):
        plugins.job_config({**base, "capacity": "c9"})
    # with Hydra's choices (as the runner passes them) the error names the preset's YAML
    with pytest.raises(InputError, match=r"capacity=c9: conf/model/ddf_tuned.yaml has no such level .*c1, c2"):
        plugins.job_config({**base, "capacity": "c9"}, {"model": "ddf_tuned"})
    hand_set = {**base, "model": plugins.plugin_yaml("model", "ddf")}
    with pytest.raises(InputError, match=r"capacity=c2: conf/model/ddf.yaml has no such level .*\(its levels: none\)"):
        plugins.job_config(hand_set, {"model": "ddf"})


def test_levels_of_takes_another_configs_levels_and_refuses_a_bad_reference():
    """gan_sdf (the thesis) shares gan_sdf_tuned's fit budgets: {levels_of: gan_sdf_tuned} in its YAML."""
    for experiment in ("pareto", "storage"):
        shared = plugins.levels("model", "gan_sdf_tuned", experiment)
        assert shared and plugins.levels("model", "gan_sdf", experiment) == shared
    thesis = {"experiment_name": "storage", "capacity": "c4", "model": plugins.plugin_yaml("model", "gan_sdf")}
    assert plugins.job_config(thesis)["train"]["max_steps"] == shared["c4"]["train"]["max_steps"]
    bad = [("mesh_lod500", "no levels of its own for pareto"),  # a preset with no pareto table
           ("gan_sdf", "no levels of its own for pareto"),  # a reference to a reference
           ("nosuch", "no such model config"), (3, "must be the entry's only key")]
    for other, why in bad:
        model = {**thesis["model"], "experiments": {"pareto": {"levels_of": other}}}
        with pytest.raises(InputError, match=f"model gan_sdf: experiments.pareto.levels_of=.*: .*{why}"):
            plugins.job_config({**thesis, "experiment_name": "pareto", "model": model})


@pytest.mark.parametrize("experiment", ["storage", "pareto"])
def test_gan_sdf_levels_set_its_fit_steps_and_others_keep_their_models(experiment):
    """The GAN's network is fixed: its capacity level is train.max_steps, taken from the level's row."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    with initialize_config_dir(CONF_DIR, version_base="1.3"):
        def composed(family, level):
            cfg = compose("config", overrides=[f"+experiment={experiment}", f"model={family}", f"capacity={level}"])
            return plugins.job_config(OmegaConf.to_container(cfg, resolve=True))
        levels = ("c1", "c2", "c3", "c4")
        gan = {lv: composed("gan_sdf_tuned", lv) for lv in levels}
        ddf = {(c := composed("ddf_tuned", lv))["train"]["max_steps"]: c["model"]["fit_steps"] for lv in levels}
    budgets = [gan[lv]["train"]["max_steps"] for lv in levels]
    assert budgets == [plugins.levels("model", "gan_sdf_tuned", experiment)[lv]["train"]["max_steps"] for lv in levels]
    assert len(set(budgets)) == 4 and len(ddf) == 1  # the bug this guards against: one budget for all levels
    assert list(ddf.items())[0][0] == list(ddf.items())[0][1]  # other families: their model's fit_steps


SEEDS = {"representations": 5, "ablation": 3, "ablation_grid": 3, "sampling": 3, "storage": 3, "pareto": 3,
         "render_time": 3, "render_shapes": 3, "gan_epochs": 5}


@pytest.mark.parametrize("experiment,n_seeds", SEEDS.items())
def test_experiments_fix_the_work_and_sweep_seeds(experiment, n_seeds):
    """Every experiment with a fixed-work budget: >= 3 seeds (5 for representations) and a steps or epochs budget.
    (convergence and paper_ddf are wall clock by design; tests/test_convergence.py checks their 3 seeds.)"""
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(CONF_DIR, version_base="1.3"):  # the sweep's own seed list, not its expansion
        cfg = compose("config", overrides=[f"+experiment={experiment}"], return_hydra_config=True)
    seeds = str(cfg.hydra.sweeper.params.seed).split(",")
    assert len(set(seeds)) == len(seeds) == n_seeds
    assert cfg.train.budget in ("steps", "epochs")


def test_sampling_fits_matched_label_counts_per_level():
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(CONF_DIR, version_base="1.3"):
        labels = {(strategy, size): compose("config", overrides=[
            f"+experiment/strategy={strategy}", f"sample_size={size}", "+experiment=sampling"]).train.n_labels
            for strategy in ("random", "pov", "surface") for size in ("xs", "l")}
    assert labels == {(s, z): n for s in ("random", "pov", "surface") for z, n in (("xs", 10000), ("l", 640000))}


@pytest.mark.slow
def test_smoke_runs_every_family_and_strategy_and_reports(tmp_path):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    run = subprocess.run([sys.executable, "-m", "ddfbench", "+experiment=smoke", f"out_dir={tmp_path}", "quiet=true"],
                         capture_output=True, text=True, env=env, timeout=900)
    assert run.returncode == 0, run.stderr[-3000:]
    records = find_records(str(tmp_path / "smoke"))
    expected = {j.key for j in grid("smoke")}
    assert {r["key"] for r in records} == expected  # every record, under the hash of its config
    for rec in records:
        assert set(RECORD_FIELDS) <= set(rec)
        assert rec["status"] == "ok", (rec["key"], rec["error"])
    assert {r["model"] for r in records} == FAMILIES  # the ddf_paper preset is family ddf
    assert {r["sampling"]["strategy"] for r in records} == SAMPLERS | {None}  # None: a family that needs no samples
    assert all(load_family(f).sample_kind is None for f in ("mesh", "grid_sdf"))
    for rec in records:  # a family that builds from the mesh gets no samples, and its record says so
        no_samples = load_family(rec["family"]).sample_kind is None
        assert no_samples == (rec["sampling"]["kind"] is None) == ("sampling_s" not in rec["cost"]), rec["key"]
        assert no_samples == ("n_samples" not in rec["sampling"]), rec["key"]
    doc = os.path.join(os.path.dirname(__file__), "..", "docs", "record.md")
    documented = set(re.findall(r"`([^`]+)`", open(doc).read()))
    for rec in records:  # docs/record.md names every key a record has, at the top and one level down
        keys = {k for k in rec if k != "_dir"} | {k for part in ("shape", "metrics", "cost", "counts", "artifacts", "env",
                                                                 "fit") for k in rec.get(part) or {}}
        assert keys <= documented, (rec["model"], sorted(keys - documented))

    out = tmp_path / "report"
    rep = subprocess.run([sys.executable, "-m", "ddfbench.report", str(tmp_path / "smoke"), "--out", str(out)],
                         capture_output=True, text=True, env=env, timeout=300)
    assert rep.returncode == 0, rep.stderr[-3000:]
    csv = pd.read_csv(out / "table.csv")
    assert len(csv[csv["model"] != "noise floor"]) == len(expected)
    assert csv["n"].fillna(1).min() >= 1 and (csv["n_failed"].fillna(0) == 0).all()
    md = (out / "table.md").read_text().splitlines()
    assert sum(line.startswith("| ") for line in md) == 1 + len(expected) + 1  # header, rows, noise floor
    tex = (out / "table.tex").read_text()
    assert tex.startswith(r"\begin{tabular}") and r"\end{tabular}" in tex and tex.count("{") == tex.count("}")
    report = (out / "report.md").read_text()
    assert all(k in report for k in expected)
    assert f"done {len(expected)}  failed 0  missing 0" in (out / "sweep_status.md").read_text()
    for kind in PLOTS_BY_EXPERIMENT["smoke"]:
        image = matplotlib.image.imread(out / f"{kind}.png")
        assert image.ndim == 3 and image.shape[0] > 100 and image.shape[1] > 100
        pdf = (out / f"{kind}.pdf").read_bytes()
        assert pdf.startswith(b"%PDF") and b"%%EOF" in pdf[-32:]


def test_a_level_the_model_lacks_is_a_failed_record_with_one_line_not_a_crash(tmp_path):
    """In a sweep the other jobs go on; in a single run the CLI prints the record's one-line error."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from ddfbench.run import runner

    with initialize_config_dir(CONF_DIR, version_base="1.3"):
        cfg = compose("config", overrides=["+experiment=pareto", "model=ddf", "capacity=c1", f"out_dir={tmp_path}"])
    rec = runner.run(OmegaConf.to_container(cfg, resolve=True), choices={"model": "ddf"})
    assert rec["status"] == "failed" and rec["model"] == "ddf" and rec["config"]["capacity"] == "c1"
    assert rec["error"] == ("capacity=c1: conf/model/ddf.yaml has no such level for experiment pareto "
                            "(its levels: none)")
    assert find_records(str(tmp_path)) and find_records(str(tmp_path))[0]["key"] == rec["key"]


def test_model_keys_an_experiment_sweeps_are_keys_of_the_models_it_sweeps():
    """A swept `model.<key>` must survive the strict model config of every model swept beside it
    (render_matched sweeps model.trace.eps_abs and omega; a YAML without the key fails every job)."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    checked = 0
    for name in sorted(f[:-5] for f in os.listdir(os.path.join(CONF_DIR, "experiment")) if f.endswith(".yaml")):
        params = OmegaConf.load(os.path.join(CONF_DIR, "experiment", f"{name}.yaml")).get("hydra", {})
        params = dict(((params or {}).get("sweeper") or {}).get("params") or {})
        keys = {k: str(v).split(",")[-1] for k, v in params.items() if k.lstrip("+").startswith("model.")}
        if not keys:
            continue
        swept = str(params.get("model", ""))
        models = plugins.members("model", name) if "members" in swept or not swept else swept.split(",")
        with initialize_config_dir(CONF_DIR, version_base="1.3"):
            for model in models:
                cfg = compose("config", overrides=[f"+experiment={name}", f"model={model}",
                                                   *(f"{k}={v}" for k, v in keys.items())])
                plain = OmegaConf.to_container(cfg, resolve=True)
                load_family(plain["model"]["family"]).configure(plain["model"])  # raises on an unknown key
                checked += 1
    assert checked >= 2  # render_matched: grid_sdf and neural_sdf_tuned


@LARGE
def test_every_experiment_has_a_quick_form_with_one_seed_and_a_step_budget():
    """`+form=quick` (conf/form/quick.yaml) composes with every experiment, keeps its models and shapes, runs one
    seed at 200 steps with a light evaluation."""
    from hydra import compose, initialize_config_dir

    from ddfbench.report.suite import Entry, expand

    for name in sorted(f[:-5] for f in os.listdir(os.path.join(CONF_DIR, "experiment")) if f.endswith(".yaml")):
        if name == "tune":  # the Optuna sweeper: trials, not a grid
            continue
        full, quick = expand(Entry(name, "x")).per_model(), expand(Entry(name, "x", ["+form=quick"])).per_model()
        assert set(quick) == set(full) and sum(quick.values()) <= sum(full.values()), name
        with initialize_config_dir(CONF_DIR, version_base="1.3"):
            cfg = compose("config", overrides=[f"+experiment={name}", "+form=quick"], return_hydra_config=True)
        assert (cfg.train.budget, cfg.train.max_steps, cfg.eval.n_points) == ("steps", 200, 10000), name
        assert str(cfg.hydra.sweeper.params.get("seed", "0")) == "0", name


def test_status_refuses_what_the_runner_refuses(capsys):
    """`report --status +train.max_step=5` said every run was missing; the runner would run none of them."""
    from ddfbench.report import status

    assert status.main("/nonexistent/default", ["+experiment=default", "+train.max_step=5"]) == 2
    assert capsys.readouterr().err.startswith("ddfbench.report --status: train.max_step: unknown key (did you mean "
                                              "max_steps")


def test_status_passes_over_a_sweep_file_that_cannot_be_read(tmp_path, capsys):
    """A multirun.yaml cut short or garbled (a sweep killed or out of disk while Hydra wrote it): `--status` names it
    in one line and takes the sweep before it; named after --status it is one line, exit 2 (both were tracebacks)."""
    import os

    from ddfbench.report import status

    sweeps = tmp_path / ".hydra" / "sweep"
    (sweeps / "old").mkdir(parents=True)
    (sweeps / "old" / "multirun.yaml").write_text("experiment_name: smoke\n")
    os.utime(sweeps / "old" / "multirun.yaml", (1e9, 1e9))  # older whatever the file system's mtime resolution
    (sweeps / "new").mkdir()
    (sweeps / "new" / "multirun.yaml").write_bytes(b"\x00\xff garbage: [")
    assert status.newest_sweep(str(tmp_path / "smoke")) == str(sweeps / "old" / "multirun.yaml")
    err = capsys.readouterr().err
    assert err.startswith(f"ddfbench: skipped {sweeps / 'new' / 'multirun.yaml'}: not a readable sweep file (")
    assert err.count("\n") == 1
    assert status.main(str(tmp_path / "smoke"), [str(sweeps / "new" / "multirun.yaml")]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"ddfbench.report --status: {sweeps / 'new' / 'multirun.yaml'}: not a readable sweep file")
