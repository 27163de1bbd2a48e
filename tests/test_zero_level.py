"""`python -m ddfbench.zero_level`: where a finished SDF run's zero level lies against the true surface.
A grid SDF built from the exact sphere has its zero level on the surface; the same grid shifted by c
reads an offset of c (inside: positive), and extracting at the median level recovers the unshifted
mesh; a run without a signed field is one line and the others are still written."""

import os
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from ddfbench.runs import find_records
from ddfbench.zero_level import main

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
    assert main([str(tmp_path / "single"), "--out", str(tmp_path / "z0"), "--n-points", "3000", "--threads", "1"]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("ddfbench.zero_level")]
    assert len(err) == 1 and recs["mesh"]["_dir"] in err[0] and "not an SDF family" in err[0]
    before = pd.read_csv(tmp_path / "z0" / "table.csv").set_index("model").loc["grid_sdf"]
    assert abs(before["offset_p50"]) < 2e-3 and before["offset_p95"] - before["offset_p5"] < 0.01
    assert 0.9 < before["median_slope"] < 1.1  # a distance field
    assert before["chamfer_l2_at_0"] == grid["metrics"]["chamfer_l2"]  # level 0 is the record's own result
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
    assert main([str(tmp_path / "nothing"), "--out", str(tmp_path / "x")]) == 2
