"""`python -m ddfbench.report.zero_level`: where a finished SDF run's zero level lies against the true surface.
A grid SDF built from the exact sphere has its zero level on the surface; the same grid shifted by c
reads an offset of c (inside: positive), and extracting at the median level recovers the unshifted
mesh; runs of other families are left out; the GAN's target scale changes its values and slopes,
not its offsets."""

import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
import torch

from ddfbench.models.gan_sdf import GanSDF
from ddfbench.report.zero_level import main, offsets, value_and_slope
from ddfbench.run.runs import find_records
from tests.conftest import rebuilt_differences

RUN = ["shape=sphere", "eval=smoke", "eval.n_points=2000", "eval.mesh_resolution=24", "sampling=random",
       "sampling.n_samples=2000", "train.budget=steps", "train.max_steps=1", "threads=1", "quiet=true", "seed=3"]
SHIFT = 0.03  # unit-cube units, a few grid cells at resolution 32 over the 1.2-wide box


def _run(out, *model):
    done = subprocess.run([sys.executable, "-m", "ddfbench", *model, *RUN, f"out_dir={out}"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]


@pytest.mark.slow
def test_zero_level_reads_a_shifted_grid_as_an_offset_and_extracting_at_its_level_undoes_it(tmp_path, capsys):
    _run(tmp_path, "model=grid_sdf", "model.resolution=32")
    _run(tmp_path, "model=mesh")
    recs = {r["model"]: r for r in find_records(str(tmp_path / "single"))}
    grid = recs["grid_sdf"]
    assert main([str(tmp_path / "single"), "--out", str(tmp_path / "z0"), "--n-points", "3000", "--threads", "1"]) == 0
    assert not [line for line in capsys.readouterr().err.splitlines() if line.startswith("ddfbench.report.zero_level")]
    table = pd.read_csv(tmp_path / "z0" / "table.csv")
    assert list(table["model"]) == ["grid_sdf"]  # the mesh run is left out, and said so
    assert "1 SDF runs (0 unreadable, 1 of other families left out)" in (tmp_path / "z0" / "table.md").read_text()
    assert rebuilt_differences(tmp_path / "z0", tmp_path / "z0_again") == []  # from its measured rows alone
    before = table.iloc[0]
    assert abs(before["offset_p50"]) < 2e-3 and before["offset_p95"] - before["offset_p5"] < 0.01
    assert 0.9 < before["median_slope"] < 1.1 and before["slope_ok"] == 1  # a distance field
    # the control: the saved grid extracted again at level 0 reproduces the run's own result
    assert before["chamfer_l2_record"] == grid["metrics"]["chamfer_l2"]
    assert before["chamfer_l2_at_0"] == pytest.approx(grid["metrics"]["chamfer_l2"], rel=1e-4)
    assert before["fscore@0.01_at_0"] == pytest.approx(grid["metrics"]["fscore"]["0.01"], abs=1e-9)
    # shift the saved field by +c: the learned surface now lies inside the sphere by c
    path = os.path.join(grid["_dir"], grid["artifacts"]["model"])
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["sdf"] = arrays["sdf"] + np.float32(SHIFT)
    np.savez(path, **arrays)
    assert main([str(tmp_path / "single"), "--out", str(tmp_path / "z1"), "--n-points", "3000", "--model",
                 "grid_sdf"]) == 0
    after = pd.read_csv(tmp_path / "z1" / "table.csv").iloc[0]
    assert after["offset_p50"] == pytest.approx(before["offset_p50"] + SHIFT, abs=1e-3)
    assert after["level"] == pytest.approx(before["level"] + SHIFT, abs=1e-5)
    # at its median level the shifted field gives the unshifted field's mesh again
    assert after["chamfer_l2_at_level"] == pytest.approx(before["chamfer_l2_at_level"], rel=0.02)
    assert after["fscore@0.01_at_level"] == pytest.approx(before["fscore@0.01_at_level"], abs=0.02)
    assert "records of code" in (tmp_path / "z1" / "table.md").read_text()
    assert after["chamfer_l2_at_0"] > 2 * after["chamfer_l2_at_level"] and not after["empty_at_level"]
    assert main([str(tmp_path / "nothing"), "--out", str(tmp_path / "x")]) == 2
    assert main([str(tmp_path / "single"), "--out", str(tmp_path / "x"), "--model", "mesh"]) == 2  # no SDF run


def test_the_gan_target_scale_scales_values_and_slopes_but_not_offsets():
    torch.manual_seed(0)
    unit, scaled = GanSDF({"target_scale": 1.0}), GanSDF({"target_scale": 4.0})
    scaled.net.load_state_dict(unit.net.state_dict())
    points = np.random.default_rng(0).uniform(-0.5, 0.5, (300, 3))
    (v1, s1), (v4, s4) = value_and_slope(unit, points), value_and_slope(scaled, points)
    assert np.allclose(v4, v1 / 4, rtol=1e-5, atol=1e-9) and np.allclose(s4, s1 / 4, rtol=1e-4)
    assert np.allclose(offsets(v4, s4), offsets(v1, s1), rtol=1e-4, atol=1e-9)
    assert (s1 > 0).all()  # a generator at initialization has a slope: the comparison is not of NaNs


def test_offsets_are_nan_where_the_gradient_gives_no_distance():
    off = offsets(np.array([0.02, 0.02, 0.02, np.nan]), np.array([0.5, 0.0, np.inf, 1.0]))
    assert off[0] == pytest.approx(0.04) and np.isnan(off[1:]).all()
