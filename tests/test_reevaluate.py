"""`python -m ddfbench.reevaluate`: a finished sweep measured again from its saved artifacts. At the
record's own point count and seed it reproduces the record's geometry metrics (so it reads the right
meshes with the right sampling); with a scene it renders each saved model; records stay unchanged."""

import json
import subprocess
import sys

import pandas as pd
import pytest

from ddfbench.reevaluate import main
from ddfbench.runs import find_records

RUN = ["-m", "model=grid_sdf,mesh", "shape=sphere", "eval=smoke", "eval.n_points=2000", "eval.mesh_resolution=20",
       "scene=none", "train.budget=steps", "threads=1", "quiet=true"]


@pytest.mark.slow
def test_reevaluation_at_the_records_settings_reproduces_them_and_renders_the_saved_models(tmp_path, capsys):
    done = subprocess.run([sys.executable, "-m", "ddfbench", *RUN, "seed=0,1", f"out_dir={tmp_path}"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    recs = {(r["model"], r["config"]["seed"]): r for r in find_records(str(tmp_path / "single"))}
    before = {k: json.dumps(r, sort_keys=True, default=str) for k, r in recs.items()}
    assert main([str(tmp_path / "single"), "--out", str(tmp_path / "re"), "--n-points", "2000", "--scene", "depth",
                 "--threads", "1"]) == 0
    rows = pd.read_csv(tmp_path / "re" / "reevaluated.csv")
    assert len(rows) == 4
    for _, row in rows.iterrows():
        m = recs[row["model"], row["seed"]]["metrics"]
        # the PLY round trip stores float32 vertices: equal to float32 precision, not bitwise
        assert row["chamfer_l2"] == pytest.approx(m["chamfer_l2"], rel=1e-5)
        assert row["f@0.01"] == pytest.approx(m["fscore"]["0.01"], abs=1e-9)
        assert row["floor_chamfer_l2"] == pytest.approx(m["noise_floor"]["chamfer_l2"], rel=1e-5)
        assert 0.95 <= row["mask_iou"] <= 1.0 and 0.0 <= row["depth_mae"] < 0.01
    full = rows[rows["model"] == "mesh"]
    assert (full["mask_iou"] == 1.0).all() and (full["depth_mae"] == 0.0).all()  # the mesh against its own BVH
    # another point count is another measurement
    assert main([str(tmp_path / "single"), "--out", str(tmp_path / "re5"), "--n-points", "500"]) == 0
    other = pd.read_csv(tmp_path / "re5" / "reevaluated.csv")
    assert "mask_iou" not in other and (other["n_points"] == 500).all()
    assert not (other.sort_values("key")["chamfer_l2"].values == rows.sort_values("key")["chamfer_l2"].values).all()
    summary = (tmp_path / "re" / "reevaluated.md").read_text()
    assert "| grid_sdf | sphere | 2 (0) |" in summary and "| mesh | sphere | 2 (0) |" in summary
    after = {(r["model"], r["config"]["seed"]): json.dumps(r, sort_keys=True, default=str)
             for r in find_records(str(tmp_path / "single"))}
    assert after == before
    capsys.readouterr()
    assert main([str(tmp_path / "nothing"), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nothing: no finished run records" in err[0]
