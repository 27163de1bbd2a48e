"""`python -m ddfbench.report.reevaluate`: a finished sweep measured again from its saved artifacts. At the
record's own point count, seed and scene it reproduces the record's geometry and image metrics (so it
reads the right meshes and loads the right networks); another point count is another measurement; an
unreadable run is one line and the others are still written; records stay unchanged."""

import json
import os
import subprocess
import sys

import pandas as pd
import pytest

from ddfbench.evaluate.metrics import evaluation_seed
from ddfbench.report.reevaluate import main
from ddfbench.run.runs import find_records
from tests.conftest import rebuilt_differences

RUN = ["-m", "model=grid_sdf,neural_sdf", "shape=sphere", "eval=smoke", "eval.n_points=2000",
       "eval.mesh_resolution=20", "scene=depth", "scene.width=24", "scene.height=24", "sampling=random",
       "sampling.n_samples=2000", "train.budget=steps", "train.max_steps=15", "threads=1", "quiet=true"]


def records(folder):
    return {(r["model"], r["config"]["seed"]): r for r in find_records(str(folder))}


@pytest.mark.slow
def test_reevaluation_at_the_records_settings_reproduces_them(tmp_path, capsys):
    done = subprocess.run([sys.executable, "-m", "ddfbench", *RUN, "seed=0,1", f"out_dir={tmp_path}"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    recs = records(tmp_path / "single")
    assert len(recs) == 4 and all(r["status"] == "ok" for r in recs.values())
    assert all(r["metrics"]["eval_seed"] == evaluation_seed(seed) != seed for (_, seed), r in recs.items())
    before = {k: json.dumps(r, sort_keys=True, default=str) for k, r in recs.items()}
    scene = ["--scene", "record", "--threads", "1"]  # each run's own 24x24 depth scene
    assert main([str(tmp_path / "single"), "--out", str(tmp_path / "re"), "--n-points", "2000", *scene]) == 0
    runs = pd.read_csv(tmp_path / "re" / "runs.csv")
    assert len(runs) == 4 and set(runs["model"]) == {"grid_sdf", "neural_sdf"}
    for _, row in runs.iterrows():
        m = recs[row["model"], row["seed"]]["metrics"]
        # the PLY round trip stores float32 vertices: equal to float32 precision, not bitwise
        assert row["chamfer_l2"] == pytest.approx(m["chamfer_l2"], rel=1e-5)
        assert row["fscore@0.01"] == pytest.approx(m["fscore"]["0.01"], abs=1e-9)
        assert row["noise_floor_chamfer_l2"] == pytest.approx(m["noise_floor"]["chamfer_l2"], rel=1e-5)
        assert row["closed"] == m["closed"] and row["components"] == m["components"] >= 1
        # rendered again from the saved network / grid on the same cameras: the image metrics of the run
        assert row["mask_iou"] == pytest.approx(m["mask_iou"], abs=1e-9) and 0.5 < row["mask_iou"]
        assert row["depth_mae"] == pytest.approx(m["depth_mae"], rel=1e-4)
    # the depth scene file (64x64) is another measurement of the same models
    assert main([str(tmp_path / "single"), "--out", str(tmp_path / "re64"), "--n-points", "2000", "--scene", "depth",
                 "--threads", "1"]) == 0
    assert (pd.read_csv(tmp_path / "re64" / "runs.csv")["depth_mae"].values != runs["depth_mae"].values).any()
    table = pd.read_csv(tmp_path / "re" / "table.csv")
    code = recs["grid_sdf", 0]["env"]["code_sha"]
    assert code and f"records of code {code[:7]}, measured by code {code[:7]}." in (tmp_path / "re" / "table.md").read_text()
    assert set(table.loc[table["n"] == 2, "model"]) == {"grid_sdf", "neural_sdf"}
    assert rebuilt_differences(tmp_path / "re", tmp_path / "re_again") == []  # from its measured rows alone
    # another point count is another measurement, and without a scene there are no image metrics
    assert main([str(tmp_path / "single"), "--out", str(tmp_path / "re5"), "--n-points", "500"]) == 0
    other = pd.read_csv(tmp_path / "re5" / "runs.csv").set_index("key")
    assert other["mask_iou"].isna().all()
    assert (other["chamfer_l2"] != runs.set_index("key").loc[other.index, "chamfer_l2"]).all()
    assert records(tmp_path / "single") and {k: json.dumps(r, sort_keys=True, default=str)
                                             for k, r in records(tmp_path / "single").items()} == before
    # a run whose model file is gone: one line naming its folder, the other runs still written, exit 1
    gone = recs["neural_sdf", 1]
    os.remove(os.path.join(gone["_dir"], gone["artifacts"]["model"]))
    capsys.readouterr()
    assert main([str(tmp_path / "single"), "--out", str(tmp_path / "re_gone"), "--n-points", "500", *scene]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("ddfbench.report.reevaluate")]
    assert len(err) == 1 and gone["_dir"] in err[0] and "no model artifact" in err[0]
    assert len(pd.read_csv(tmp_path / "re_gone" / "runs.csv")) == 3
    assert main([str(tmp_path / "nothing"), "--out", str(tmp_path / "x")]) == 2
    capsys.readouterr()  # a family that stores no network weights cannot be stored as float16
    assert main([str(tmp_path / "single"), "--out", str(tmp_path / "g"), "--model", "grid_sdf", "--store-as",
                 "float16"]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("ddfbench.report.reevaluate")]
    assert len(err) == 2 and all("family grid_sdf has no storage_dtype" in line for line in err)  # its two runs


DDF_RUN = ["-m", "model=ddf", "model.width=32", "model.depth=2", "model.storage_dtype=float32,float16", "shape=sphere",
           "eval=smoke", "eval.n_points=2000", "eval.mesh_resolution=20", "scene=none", "sampling=random",
           "sampling.n_samples=2000", "train.budget=steps", "train.max_steps=60", "threads=1", "quiet=true"]


@pytest.mark.slow
def test_a_float16_run_measures_its_rounded_network_as_store_as_float16_measures_the_float32_run(tmp_path, capsys):
    done = subprocess.run([sys.executable, "-m", "ddfbench", *DDF_RUN, f"out_dir={tmp_path}"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    runs = {r["config"]["model"]["storage_dtype"]: r for r in find_records(str(tmp_path / "single"))}
    assert set(runs) == {"float32", "float16"} and all(r["status"] == "ok" for r in runs.values())
    half, full = runs["float16"]["metrics"], runs["float32"]["metrics"]
    assert half["chamfer_l2"] != full["chamfer_l2"]  # the same fit, measured after its float16 rounding
    assert main([str(tmp_path / "single"), "--out", str(tmp_path / "re"), "--n-points", "2000",
                 "--model", "ddf", "--store-as", "float16"]) == 0
    again = pd.read_csv(tmp_path / "re" / "runs.csv").set_index("key")
    for rec in runs.values():  # both records stored as float16 and meshed anew: the float16 run's numbers
        assert again.loc[rec["key"], "chamfer_l2"] == pytest.approx(half["chamfer_l2"], rel=1e-5)
        assert again.loc[rec["key"], "storage_bytes"] == runs["float16"]["cost"]["storage_bytes"]
    assert runs["float16"]["cost"]["storage_bytes"] < 0.6 * runs["float32"]["cost"]["storage_bytes"]
    pairs = (tmp_path / "re" / "paired.md").read_text()  # each run against its own saved mesh: 2 pairs
    rows = [line.split(" | ") for line in pairs.splitlines() if line.startswith("| stored as float16 |")]
    assert len(rows) == 2 and all(row[1] == "2" for row in rows)  # chamfer and F@0.01, 2 pairs each
    # every table, paired.md too, regenerates byte for byte from the measured rows saved beside it
    assert rebuilt_differences(tmp_path / "re", tmp_path / "re_again") == []
    assert {p.name for p in (tmp_path / "re_again").iterdir()} >= {"table.md", "table.csv", "runs.csv", "paired.md"}
    capsys.readouterr()  # a float16 record cannot be stored as float32: its rounding stays
    assert main([str(tmp_path / "single"), "--out", str(tmp_path / "w"), "--model", "ddf", "--store-as", "float32"]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("ddfbench.report.reevaluate")]
    assert len(err) == 1 and runs["float16"]["_dir"] in err[0] and "stored as float16 already" in err[0]


def test_a_scene_preset_is_composed_with_the_presets_it_builds_on():
    """normals.yaml says `defaults: [depth, _self_]`: read as a job reads it, it has depth's cameras and its own
    outputs (read as a plain YAML it had a `defaults` key every render refused)."""
    from ddfbench.core.errors import InputError
    from ddfbench.report.reevaluate import scene_config

    normals = scene_config("normals")
    assert "defaults" not in normals and normals["outputs"] == ["depth", "mask", "normal"]
    assert normals["cameras"] == scene_config("depth")["cameras"]
    with pytest.raises(InputError, match="scene=fancy: no conf/scene/fancy.yaml"):
        scene_config("fancy")


def test_a_bad_count_names_the_flag_given_and_the_tool_s_own_command(tmp_path, capsys):
    from ddfbench.report.zero_level import main as zero_level_main

    assert zero_level_main([str(tmp_path), "--out", str(tmp_path / "z"), "--n-points", "0"]) == 2
    assert capsys.readouterr().err == "ddfbench.report.zero_level: --n-points 0: must be an integer >= 1\n"
    assert main([str(tmp_path), "--out", str(tmp_path / "r"), "--threads", "-1"]) == 2
    assert capsys.readouterr().err == "ddfbench.report.reevaluate: --threads -1: must be an integer >= 0 (0: torch's default)\n"
    with pytest.raises(SystemExit):
        main(["--help"])
    assert capsys.readouterr().out.startswith("usage: python -m ddfbench.report.reevaluate")
