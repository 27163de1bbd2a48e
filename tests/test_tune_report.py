"""A tuning study's report (ddfbench.report.tune) is written from its records into a compact record of its own
(trials.csv, study.json) and regenerates from that alone: the committed studies byte for byte, a hand edit caught,
the preset column the preset run's values rather than a later YAML's, and an unreadable study one line."""

import json
import os
import shutil

import pytest

from ddfbench.core import plugins
from ddfbench.core.errors import InputError
from ddfbench.fit.tune import search_space
from ddfbench.report import index
from ddfbench.report import tune as tune_report
from ddfbench.report.regenerate import main as regenerate_main

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
COMMITTED = ("tune", "tune_line_grid")  # wall-clock studies whose run records were lost: their trial tables remain


def _record(folder, key, model, overrides, objective, started, config_model):
    rec = {"schema_version": 1, "key": key, "status": "ok", "experiment": "tune", "model": model, "shape": {},
           "metrics": {"chamfer_l2": objective}, "cost": {"fit_s": 2.5}, "fit": {"steps": 40},
           "config": {"train": {"max_seconds": 2}, "model": config_model}, "overrides": overrides,
           "env": {"threads": 1, "cpu": "x86_64", "code_sha": "abcdef0123"}, "started": started}
    os.makedirs(folder / key)
    (folder / key / "record.json").write_text(json.dumps(rec))


def _edit_json(folder, change):
    head = json.loads((folder / "study.json").read_text())
    change(head)
    (folder / "study.json").write_text(json.dumps(head))


@pytest.fixture
def study(tmp_path):
    """Two trials of neural_sdf and its preset run, whose lr (0.0123) is not the one conf/model/neural_sdf.yaml
    gives today: the YAML changed after the study ran."""
    records = tmp_path / "results" / "tune"
    space = list(search_space("neural_sdf"))
    drawn = [f"{path}=0.5" if path == "model.delta" else f"{path}=7" for path in space]
    _record(records, "a" * 16, "neural_sdf", ["model=neural_sdf", *drawn], 3e-4, "2026-01-01T00:00:01", {})
    _record(records, "b" * 16, "neural_sdf", ["model=neural_sdf", *drawn[:-1], f"{space[-1]}=null"], 2e-4,
            "2026-01-01T00:00:02", {})
    _record(records, "c" * 16, "neural_sdf", ["model=neural_sdf"], 5e-4, "2026-01-01T00:00:03",
            {"lr": 0.0123, "lr_schedule": "constant", "width": 96, "depth": 5, "n_harmonics": 5, "batch": 512,
             "delta": 0.2, "w_eikonal": 0.0})
    out = tmp_path / "reports" / "tune"
    tune_report.write(str(records), str(out))
    return out


def test_the_preset_column_is_the_preset_runs_config_and_the_folder_is_portable(study):
    best = (study / "best.md").read_text()
    assert "| model.lr | 7 | 0.0123 |" in best  # the preset run's lr, not the YAML's
    assert "| model.w_eikonal | null | 0.0 |" in best  # a drawn 'null' stays the string overridden
    assert "## neural_sdf: trial 1, CD-L2 x10^3 0.2 (40 steps, 2.5 s)" in best
    assert "The preset's own values at the same budget: CD-L2 x10^3 0.5 (40 steps)." in best
    assert "3 records from `<out_dir>/tune` (code abcdef0; threads 1; cpu x86_64)." in best
    assert str(study.parent.parent) not in "".join(p.read_text() for p in study.iterdir() if p.suffix != ".png")


def test_a_written_study_regenerates_and_a_hand_edit_or_a_changed_preset_fails(study, capsys):
    reports = str(study.parent)
    assert index.provenance(str(study)) == index.Provenance(3, ["abcdef0"], index.FROM_TRIALS)
    assert regenerate_main(["--from-records", "--check", "--reports", reports, "--readme", "none.md"]) == 0
    best = study / "best.md"
    best.write_text(best.read_text().replace("CD-L2 x10^3 0.2", "CD-L2 x10^3 0.19"))
    assert regenerate_main(["--from-records", "--check", "--reports", reports, "--readme", "none.md"]) == 1
    assert f"{best} differs" in capsys.readouterr().err
    assert regenerate_main(["--from-records", "--reports", reports, "--readme", "none.md"]) == 0  # rewritten
    assert "CD-L2 x10^3 0.2 (40" in best.read_text()
    head = json.loads((study / "study.json").read_text())
    head["presets"]["neural_sdf"]["model.lr"] = 0.5
    (study / "study.json").write_text(json.dumps(head))
    assert regenerate_main(["--from-records", "--check", "--reports", reports, "--readme", "none.md"]) == 1
    assert f"{best} differs" in capsys.readouterr().err


def test_without_a_preset_run_the_preset_column_is_the_yaml(study, tmp_path):
    records = tmp_path / "results" / "tune"
    shutil.rmtree(records / ("c" * 16))
    tune_report.write(str(records), str(tmp_path / "no_preset"))
    best = (tmp_path / "no_preset" / "best.md").read_text()
    assert f"| model.lr | 7 | {plugins.model_defaults('neural_sdf')['lr']} |" in best
    assert "The preset's own values" not in best  # no preset run: no objective to give


def test_a_rebuild_reads_no_conf(study, tmp_path, monkeypatch):
    def refuse(*_args):
        raise AssertionError("a rebuild read conf/")

    monkeypatch.setattr(tune_report, "search_space", refuse)
    monkeypatch.setattr(plugins, "model_defaults", refuse)
    tune_report.rebuild(str(study), str(tmp_path / "rebuilt"), draw=False)
    for name in ("trials.csv", "trials.md", "best.md", "space.md"):
        assert (tmp_path / "rebuilt" / name).read_bytes() == (study / name).read_bytes(), name


@pytest.mark.parametrize("name", COMMITTED)
def test_the_committed_studies_regenerate_byte_for_byte(name, tmp_path):
    tune_report.rebuild(os.path.join(ROOT, "reports", name), str(tmp_path), draw=False)
    for file in ("trials.csv", "trials.md", "best.md", "space.md"):
        with open(os.path.join(ROOT, "reports", name, file), "rb") as committed:
            assert (tmp_path / file).read_bytes() == committed.read(), file


@pytest.mark.parametrize("edit, message", [
    (lambda d: (d / "study.json").write_text("{"), "study.json: not a readable JSON file"),
    (lambda d: (d / "study.json").write_text('{"provenance": 1}'), "study.json: needs a JSON object with provenance"),
    (lambda d: (d / "trials.csv").write_text("model,kind\nddf,trial\n"), "trials.csv: no column trial, objective"),
    (lambda d: (d / "trials.csv").write_text((d / "trials.csv").read_text().replace("\nddf,", "\nddf_x,", 1)),
     "trials.csv: model ddf_x has no search space in study.json"),
    (lambda d: (d / "trials.csv").write_text((d / "trials.csv").read_text().splitlines()[0] + "\n"),
     "trials.csv: model ddf has no trial row"),
    (lambda d: (d / "trials.csv").write_text((d / "trials.csv").read_text().replace(",ok,", ",ok,x", 1)),
     "trials.csv: column steps must hold numbers"),
    (lambda d: (d / "trials.csv").write_text((d / "trials.csv").read_text().replace("ddf,trial,1,", "ddf,trial,0.5,")),
     "trials.csv: ddf's trial numbers must be whole, given and distinct"),
    (lambda d: (d / "trials.csv").write_text((d / "trials.csv").read_text().replace("ddf,trial,1,", "ddf,trial,0,")),
     "trials.csv: ddf's trial numbers must be whole, given and distinct"),
    (lambda d: (d / "trials.csv").write_text((d / "trials.csv").read_text().replace("ddf,trial,", "ddf,trail,", 1)),
     "trials.csv: kind 'trail' is not trial or preset"),
    (lambda d: _edit_json(d, lambda h: h["presets"].pop("ddf")), "study.json: presets.ddf must give a value"),
    (lambda d: _edit_json(d, lambda h: h["spaces"]["ddf"].update({"model.lr": "log"})),
     "study.json: spaces.ddf must map each key to"),
])
def test_an_unreadable_study_is_one_line_naming_the_file(tmp_path, edit, message, capsys):
    folder = tmp_path / "tune"
    shutil.copytree(os.path.join(ROOT, "reports", "tune"), folder)
    edit(folder)
    with pytest.raises(InputError, match=message):
        tune_report.read(str(folder))
    assert regenerate_main(["--from-records", "--check", "--reports", str(tmp_path), "--readme", "none.md"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
