"""`python -m ddfbench.report.pool_seeds`: a two-seed table and later one-seed reports pooled into one table."""

import math

import pandas as pd
import pytest

from ddfbench.core.errors import InputError
from ddfbench.report.pool_seeds import COLUMNS, main, pooled_table


def write_folder(root, later_seeds: dict[int, float]):
    """table.csv of seeds 0-1 with chamfer_l2 mean 3e-5 (std √2·1e-5) and seed0/table.csv with 4e-5 (so seed 1 was
    2e-5), every other column 1; one seed<K>/runs.csv a later seed with chamfer_l2 = later_seeds[K]."""
    (root / "seed0").mkdir()
    tables = ((root / "table.csv", 2, 3e-5, "k0 k1"), (root / "seed0" / "table.csv", 1, 4e-5, "k0"))
    for path, n, chamfer, keys in tables:
        row = {"model": "gan_sdf_tuned", "n": n, "keys": keys}
        for column, _, _ in COLUMNS:
            row[f"{column}_mean"], row[f"{column}_std"] = 1.0, 0.0
        row["chamfer_l2_mean"], row["chamfer_l2_std"] = chamfer, (math.sqrt(2) * 1e-5 if n == 2 else None)
        pd.DataFrame([row, {"model": "noise floor"}]).to_csv(path, index=False)
    for seed, value in later_seeds.items():
        (root / f"seed{seed}").mkdir()
        runs = {"model": ["gan_sdf_tuned", "gan_sdf_tuned"], "status": ["ok", "failed"], "seed": [seed, seed]}
        runs.update({column: [1.0, 9.0] for column, _, _ in COLUMNS})
        runs["chamfer_l2"] = [value, 1.0]
        pd.DataFrame(runs).to_csv(root / f"seed{seed}" / "runs.csv", index=False)


def test_the_pool_recovers_both_seeds_and_adds_the_later_ones(tmp_path):
    write_folder(tmp_path, {3: 6e-5, 2: 8e-5})
    lines = pooled_table(str(tmp_path), "gan_sdf_tuned", " here").splitlines()
    assert lines[0].startswith("# gan_sdf_tuned here: seeds 0, 1, 2, 3 pooled")
    assert "n = 4" in lines[2] and lines[2].endswith("| seed 0 | seed 1 | seed 2 | seed 3 |")
    chamfer = next(line for line in lines if line.startswith("| CD-L2 ×10³ |")).split(" | ")
    # seeds 0-3 scaled by 1e3: 0.04, 0.02 (2 × 0.03 − 0.04), 0.08, 0.06 -> mean 0.05; the failed run's 1.0 left out
    assert chamfer[1].startswith("0.05 ± ")
    assert chamfer[2:5] == ["0.04", "0.02", "0.08"] and chamfer[5].rstrip(" |") == "0.06"


def test_seed_zero_must_be_one_of_the_pairs_runs(tmp_path):
    write_folder(tmp_path, {2: 6e-5})
    table = pd.read_csv(tmp_path / "seed0" / "table.csv")
    table.loc[0, "keys"] = "k9"
    table.to_csv(tmp_path / "seed0" / "table.csv", index=False)
    with pytest.raises(InputError, match="not one of table.csv's two"):
        pooled_table(str(tmp_path), "gan_sdf_tuned", "")


def test_seed_zero_must_lie_where_the_pairs_std_puts_it(tmp_path, capsys):
    write_folder(tmp_path, {2: 6e-5})
    table = pd.read_csv(tmp_path / "seed0" / "table.csv")
    table.loc[0, "chamfer_l2_mean"] = 4.5e-5  # 1.5e-5 from the mean, where std/√2 = 1e-5
    table.to_csv(tmp_path / "seed0" / "table.csv", index=False)
    assert main([str(tmp_path)]) == 2
    assert "chamfer_l2 not std/√2 from table.csv's two-seed mean" in capsys.readouterr().err


def test_a_seed_folder_must_hold_its_own_seed(tmp_path):
    write_folder(tmp_path, {2: 6e-5})
    (tmp_path / "seed2").rename(tmp_path / "seed5")
    with pytest.raises(InputError, match="seed5"):
        pooled_table(str(tmp_path), "gan_sdf_tuned", "")
    (tmp_path / "again").mkdir()
    write_folder(tmp_path / "again", {})
    (tmp_path / "again" / "seed1").mkdir()  # seed 1 is table.csv's; a seed1/ report would count it twice
    pd.DataFrame({"model": ["gan_sdf_tuned"], "status": ["ok"], "seed": [1]}).to_csv(
        tmp_path / "again" / "seed1" / "runs.csv", index=False)
    with pytest.raises(InputError, match="2 or above"):
        pooled_table(str(tmp_path / "again"), "gan_sdf_tuned", "")


def test_the_command_prints_the_table(tmp_path, capsys):
    write_folder(tmp_path, {2: 6e-5})
    assert main([str(tmp_path), "--title", " x"]) == 0
    assert capsys.readouterr().out == pooled_table(str(tmp_path), "gan_sdf_tuned", " x")
