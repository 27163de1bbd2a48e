"""A family or a sampler is a plugin: one module and one YAML, nothing else touched.

The slow test copies the package and the config tree, adds a copy of grid_sdf under a new name and a
copy of the random sampler under a new name (one .py and one .yaml each), and shows that both join
every experiment their YAML names, run in the smoke sweep and reach the report table and plots, and
that the copied family runs in pareto and storage at its own levels.
"""

import json
import os
import shutil
import subprocess
import sys

import pandas as pd
import pytest

from ddfbench.core import plugins
from ddfbench.core.errors import InputError
from ddfbench.core.plugins import CONF_DIR
from ddfbench.models import load_family
from ddfbench.run.runs import find_records

PACKAGE_DIR = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(plugins.__file__))))


def test_family_config_is_the_yaml_overlaid_and_rejects_unknown_keys():
    mesh = load_family("mesh")({"faces": 10})
    expected = {k: v for k, v in plugins.defaults("model", "mesh").items() if k != "family"}
    assert mesh.cfg == {**expected, "faces": 10}  # the YAML's keys, cfg's values where it gives them
    with pytest.raises(InputError) as err:
        load_family("ddf")({"widht": 64})
    line = str(err.value)
    assert "\n" not in line and line.startswith("model.widht: unknown key (known: ") and "width" in line


def test_family_config_rejects_a_value_of_the_wrong_type():
    with pytest.raises(InputError, match=r"model.resolution='big': must be a number"):
        load_family("grid_sdf")({"resolution": "big"})
    with pytest.raises(InputError, match=r"model.trace.epss: unknown key"):
        load_family("grid_sdf")({"trace": {"epss": 1e-3}})


def test_a_preset_takes_its_missing_keys_from_its_family_yaml():
    paper = plugins.plugin_yaml("model", "ddf_paper")
    assert "entry_share" not in paper
    rep = load_family("ddf")({k: v for k, v in paper.items() if k != "experiments"})
    assert rep.cfg["entry_share"] == plugins.defaults("model", "ddf")["entry_share"]
    assert rep.cfg["width"] == paper["width"] != plugins.defaults("model", "ddf")["width"]


def test_misspelt_override_ends_the_run_with_one_line(tmp_path):
    run = subprocess.run([sys.executable, "-m", "ddfbench", "model=ddf", "model.widht=64", f"out_dir={tmp_path}"],
                         capture_output=True, text=True, timeout=120, cwd=str(tmp_path),
                         env=dict(os.environ, PYTHONPATH=PACKAGE_DIR))
    assert run.returncode != 0
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ddfbench: model.widht: unknown key (did you mean width? known: ")
    assert "width" in lines[0] and "batch" in lines[0]
    assert not os.path.exists(tmp_path / "single")  # nothing ran


def _copy_tree(root):
    """The package (its conf link kept: it reads the copy) and conf/ copied under root, with grid_copy (a family) and
    random_copy (a sampler) added."""
    ignore = shutil.ignore_patterns("__pycache__")
    shutil.copytree(os.path.join(PACKAGE_DIR, "ddfbench"), root / "ddfbench", ignore=ignore, symlinks=True)
    shutil.copytree(CONF_DIR, root / "conf", ignore=ignore)
    pkg, conf = root / "ddfbench", root / "conf"
    family = (pkg / "models" / "grid_sdf.py").read_text()
    (pkg / "models" / "grid_copy.py").write_text(family.replace('family = "grid_sdf"', 'family = "grid_copy"'))
    (conf / "model" / "grid_copy.yaml").write_text(
        (conf / "model" / "grid_sdf.yaml").read_text().replace("family: grid_sdf", "family: grid_copy"))
    shutil.copy(pkg / "sampling" / "random.py", pkg / "sampling" / "random_copy.py")
    (conf / "sampling" / "random_copy.yaml").write_text(
        (conf / "sampling" / "random.yaml").read_text().replace("strategy: random", "strategy: random_copy"))


@pytest.mark.slow
def test_a_copied_family_and_sampler_join_the_experiments_and_the_report(tmp_path):
    root = tmp_path / "tree"
    _copy_tree(root)
    env = dict(os.environ, PYTHONPATH=str(root), PYTHONUNBUFFERED="1")
    probe = ("import json; from ddfbench.core import plugins; from ddfbench.report.status import expected_grid as g;"
             "e = ['default', 'representations', 'render_time', 'pareto', 'storage', 'smoke'];"
             "print(json.dumps({'models': {x: plugins.members('model', x) for x in e},"
             " 'samplers': plugins.members('sampling', 'sampling'),"
             " 'smoke': [j.swept for j in g('/x/smoke', ['+experiment=smoke'])[0]]}))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, cwd=str(root),
                         timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    found = json.loads(out.stdout)
    assert all("grid_copy" in models for models in found["models"].values()), found["models"]
    assert "random_copy" in found["samplers"]
    smoke = {tuple(sorted(s)) for s in found["smoke"]}
    assert ("model=grid_copy", "sampling=random_copy") in smoke and ("model=ddf", "sampling=random_copy") in smoke

    # Two runs of the smoke sweep: the copied family (it needs no samples) and the DDF on the copied sampler.
    run = subprocess.run([sys.executable, "-m", "ddfbench", "+experiment=smoke", "hydra.sweeper.params=null",
                          "model=grid_copy,ddf", "sampling=random_copy",
                          f"out_dir={tmp_path / 'out'}", "quiet=true", "threads=1"],
                         capture_output=True, text=True, env=env, cwd=str(root), timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    report = subprocess.run([sys.executable, "-m", "ddfbench.report", str(tmp_path / "out" / "smoke"),
                             "--out", str(tmp_path / "report"), "--plots", "none"],  # the plots' legends: below
                            capture_output=True, text=True, env=env, cwd=str(root), timeout=300)
    assert report.returncode == 0, report.stderr[-3000:]
    table = pd.read_csv(tmp_path / "report" / "table.csv")
    rows = table[table["model"] != "noise floor"]
    assert set(rows["model"]) == {"grid_copy", "ddf"} and (rows["n_failed"].fillna(0) == 0).all()
    ddf_row = rows[rows["model"] == "ddf"].iloc[0]
    assert ddf_row["n_samples_mean"] > 0 and ddf_row["sampling_s_mean"] > 0  # the copied sampler made its labels
    grid_row = rows[rows["model"] == "grid_copy"].iloc[0]
    assert pd.isna(grid_row["n_samples_mean"]) and pd.isna(grid_row["sampling_s_mean"])  # a grid needs none
    legends = _plot_legends(tmp_path / "out" / "smoke", env, root)
    assert "grid_copy" in legends["pareto"] and "ddf" in legends["pareto"]
    assert any("random_copy" in label for label in legends["sampling"])

    # One job of the copied family in each experiment where it has levels of its own (its membership of
    # default and representations is checked above; their jobs are the smoke run's code path).
    levels = plugins.levels("model", "grid_sdf", "pareto")["c2"]["model"]
    for experiment, extra in (("pareto", ["capacity=c2"]), ("storage", ["capacity=c2"])):
        job = subprocess.run([sys.executable, "-m", "ddfbench", f"+experiment={experiment}", "hydra.sweeper.params=null",
                              "model=grid_copy", "shape.name=sphere", "eval=smoke", "scene=none", *extra,
                              f"out_dir={tmp_path / 'jobs'}", "quiet=true", "threads=1"],
                             capture_output=True, text=True, env=env, cwd=str(root), timeout=300)
        assert job.returncode == 0, (experiment, job.stderr[-2000:])
        rec = find_records(str(tmp_path / "jobs" / experiment))
        assert len(rec) == 1 and rec[0]["status"] == "ok" and rec[0]["model"] == "grid_copy", experiment
        if experiment == "pareto":
            assert rec[0]["config"]["model"]["resolution"] == levels["resolution"]
        if experiment == "storage":
            own = plugins.levels("model", "grid_sdf", "storage")["c2"]["model"]
            assert all(rec[0]["config"]["model"][k] == v for k, v in own.items())


def _plot_legends(records_dir, env, root):
    """{plot kind: legend labels} of the smoke report's plots, drawn in the copied tree."""
    script = ("import json, sys; from ddfbench.report import plots; from ddfbench.run.runs import find_records\n"
              "seen = {}\n"
              "def keep(fig, out_dir, name):\n"
              "    seen[name] = [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()]\n"
              "    return []\n"
              "plots._save = keep\n"
              "plots.write_plots(find_records(sys.argv[1]), '/unused', plots.plots_for('smoke'))\n"
              "print(json.dumps(seen))")
    out = subprocess.run([sys.executable, "-c", script, str(records_dir)], capture_output=True, text=True, env=env,
                         cwd=str(root), timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout)


def test_command_line_overrides_are_checked_against_the_named_plugin():
    from ddfbench.cli import checked_overrides

    # a key the preset leaves to its family's YAML is added (Hydra would refuse `model.entry_share=` on it)
    assert checked_overrides(["model=ddf_paper", "model.entry_share=0.3", "seed=1"]) == \
        ["model=ddf_paper", "++model.entry_share=0.3", "seed=1"]
    assert checked_overrides(["model=ddf", "model.width=64"]) == ["model=ddf", "model.width=64"]
    with pytest.raises(InputError, match=r"^sampling.n_sampels: unknown key \(did you mean n_samples, max_samples\? known: "):
        checked_overrides(["sampling=random", "sampling.n_sampels=5"])
    with pytest.raises(InputError, match=r"^model.faces: unknown key"):
        checked_overrides(["model=ddf", "model.faces=5"])  # a mesh key, not a DDF's


def test_a_swept_list_of_plugins_is_checked_config_by_config_before_any_job():
    from ddfbench.cli import checked_overrides

    # Hydra's own refusal was five lines, telling the user to try `+model.resolution=`, which each job then refuses
    with pytest.raises(InputError, match=r"^model.resolution: model=mesh of this sweep has no key 'resolution' "
                                         r"\(known: backend, faces, family\); sweep the models that have it"):
        checked_overrides(["-m", "model=grid_sdf,mesh", "model.resolution=64"])
    with pytest.raises(InputError, match=r"^sampling.s_p: sampling=random of this sweep has no key 's_p'"):
        checked_overrides(["-m", "sampling=surface,random", "sampling.s_p=20"])
    # every swept preset has the key, one only through its family's YAML: added for all (++), as for one preset
    assert checked_overrides(["-m", "model=ddf,ddf_paper", "model.entry_share=0.3"]) == \
        ["-m", "model=ddf,ddf_paper", "++model.entry_share=0.3"]
    assert checked_overrides(["-m", "model=ddf,ddf_tuned", "model.lr=1e-3"])[-1] == "model.lr=1e-3"  # in both YAMLs


def test_the_cli_shortens_openmp_spin_unless_the_environment_sets_a_wait_policy(monkeypatch):
    from ddfbench import cli

    for name in ("GOMP_SPINCOUNT", "OMP_WAIT_POLICY"):
        monkeypatch.delenv(name, raising=False)
    cli.short_openmp_spin()
    assert os.environ["GOMP_SPINCOUNT"] == cli.OPENMP_SPIN == "1000"
    monkeypatch.setenv("GOMP_SPINCOUNT", "5")
    cli.short_openmp_spin()
    assert os.environ["GOMP_SPINCOUNT"] == "5"  # the user's own value stays
    monkeypatch.delenv("GOMP_SPINCOUNT")
    monkeypatch.setenv("OMP_WAIT_POLICY", "ACTIVE")
    cli.short_openmp_spin()
    assert "GOMP_SPINCOUNT" not in os.environ  # a wait policy of the user's: its spin is libgomp's to choose
