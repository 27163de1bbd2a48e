"""`python -m ddfbench.report.pool_seeds`: a report's runs and later one-seed reports pooled into one table."""

import os
import re

import pandas as pd
import pytest

from ddfbench.core.errors import InputError
from ddfbench.report.pool_seeds import COLUMNS, main, pooled_table

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def write_runs(path, seeds: dict[int, float]):
    """runs.csv with a finished run per seed (chamfer_l2 = seeds[K], every other column 1) and a failed one
    (every column 9)."""
    path.parent.mkdir(exist_ok=True)
    rows = [{"model": "gan_sdf_tuned", "status": "ok", "seed": seed, **{c: 1.0 for c, _, _ in COLUMNS},
             "chamfer_l2": value} for seed, value in seeds.items()]
    rows.append({"model": "gan_sdf_tuned", "status": "failed", "seed": 7, **{c: 9.0 for c, _, _ in COLUMNS}})
    rows.append({"model": "noise floor", "status": "ok", "seed": 8, **{c: 9.0 for c, _, _ in COLUMNS}})
    pd.DataFrame(rows).to_csv(path, index=False)


def write_folder(root, later_seeds: dict[int, float]):
    """runs.csv of seeds 0 (4e-5) and 1 (2e-5); one seed<K>/runs.csv a later seed with chamfer_l2 = later_seeds[K]."""
    write_runs(root / "runs.csv", {1: 2e-5, 0: 4e-5})
    for seed, value in later_seeds.items():
        write_runs(root / f"seed{seed}" / "runs.csv", {seed: value})


def test_the_pool_takes_the_folders_runs_and_adds_the_later_seeds_in_seed_order(tmp_path):
    write_folder(tmp_path, {3: 6e-5, 2: 8e-5})
    lines = pooled_table(str(tmp_path), "gan_sdf_tuned", " here").splitlines()
    assert lines[0] == "# gan_sdf_tuned here: seeds 0, 1, 2, 3 pooled (ddfbench.report.pool_seeds)"
    assert "n = 4" in lines[2] and lines[2].endswith("| seed 0 | seed 1 | seed 2 | seed 3 |")
    chamfer = next(line for line in lines if line.startswith("| CD-L2 ×10³ |")).split(" | ")
    # seeds 0-3 scaled by 1e3: 0.04, 0.02, 0.08, 0.06 -> mean 0.05; the failed run's and the floor's 9.0 left out
    assert chamfer[1].startswith("0.05 ± ")
    assert chamfer[2:5] == ["0.04", "0.02", "0.08"] and chamfer[5].rstrip(" |") == "0.06"


def test_a_seed_folder_must_hold_one_run_of_its_own_seed_and_no_seed_counts_twice(tmp_path):
    write_folder(tmp_path, {2: 6e-5})
    (tmp_path / "seed2").rename(tmp_path / "seed5")
    with pytest.raises(InputError, match=r"seed5/runs.csv: must hold one finished run .* \(holds 1\)"):
        pooled_table(str(tmp_path), "gan_sdf_tuned", "")
    (tmp_path / "seed5").rename(tmp_path / "seed2")
    write_runs(tmp_path / "seed2" / "runs.csv", {2: 6e-5, 3: 7e-5})  # two finished runs in one seed's folder
    with pytest.raises(InputError, match=r"seed2/runs.csv: must hold one finished run .* \(holds 2\)"):
        pooled_table(str(tmp_path), "gan_sdf_tuned", "")
    (tmp_path / "again").mkdir()
    write_folder(tmp_path / "again", {1: 3e-5})  # seed 1 is also the folder's own runs.csv's
    with pytest.raises(InputError, match=r"seed 1 is pooled twice: in .*again/runs.csv, .*again/seed1/runs.csv"):
        pooled_table(str(tmp_path / "again"), "gan_sdf_tuned", "")


@pytest.mark.parametrize("damage, says", [
    (lambda root: (root / "runs.csv").unlink(), r"runs.csv: not a report's runs.csv \(.*No such file"),
    (lambda root: (root / "seed2" / "runs.csv").unlink(), r"seed2/runs.csv: not a report's runs.csv"),
    (lambda root: pd.read_csv(root / "runs.csv").drop(columns="seed").to_csv(root / "runs.csv", index=False),
     r"runs.csv: not a report's runs.csv \(no column seed\)"),
    (lambda root: (root / "runs.csv").write_text("model,status,seed\na,ok,1,2\n"), r"runs.csv: not a report's"),
    (lambda root: pd.read_csv(root / "runs.csv").assign(seed="x").to_csv(root / "runs.csv", index=False),
     r"runs.csv: not a report's runs.csv \(invalid literal"),
])
def test_a_bad_runs_file_is_one_line_naming_it(tmp_path, capsys, damage, says):
    write_folder(tmp_path, {2: 6e-5})
    damage(tmp_path)
    assert main([str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("ddfbench.report.pool_seeds: ")
    assert re.search(says, err), err


def test_a_model_with_no_finished_run_is_an_error_not_an_empty_table(tmp_path):
    write_folder(tmp_path, {})
    with pytest.raises(InputError, match=r"runs.csv: no finished run of ddf"):
        pooled_table(str(tmp_path), "ddf", "")


def test_the_command_prints_the_table(tmp_path, capsys):
    write_folder(tmp_path, {2: 6e-5})
    assert main([str(tmp_path), "--title", " x"]) == 0
    assert capsys.readouterr().out == pooled_table(str(tmp_path), "gan_sdf_tuned", " x")


def test_the_committed_pooled_table_is_what_the_committed_runs_give(capsys):
    """reports/gan_epochs_tuned/pooled.md is the command's output on the folder's committed runs.csv files (CI's
    regenerate check does not cover it: it is no report's output)."""
    folder = os.path.join(ROOT, "reports", "gan_epochs_tuned")
    assert main([folder]) == 0
    with open(os.path.join(folder, "pooled.md"), encoding="utf-8") as fh:
        assert capsys.readouterr().out == fh.read()
