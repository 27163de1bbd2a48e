"""`python -m ddfbench.report.edge_error`: where a run's depth and mask errors lie, by distance to the edges of
the oracle's frame. Edges are found at mask changes and depth steps above the jump, not on a ramp;
bands follow the Euclidean distance in pixels; errors placed on known pixels land in their bands;
on a real run the pooled figures equal the record's own image metrics, and a run without renders is
named on stderr while the others are written."""

import json
import math
import os
import shutil
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from ddfbench.report.edge_error import BANDS, band_counts, bands, edge_pixels, figures, main
from ddfbench.run.runs import find_records
from tests.conftest import rebuilt_differences

BAND = {name: i for i, (name, _) in enumerate(BANDS)}


def _square(n=10, lo=3, hi=7, depth=1.0):
    mask = np.zeros((n, n), bool)
    mask[lo:hi, lo:hi] = True
    return np.where(mask, np.float32(depth), np.float32(np.inf)), mask


def test_edges_are_the_pixels_on_either_side_of_a_mask_change_or_a_depth_step():
    depth, mask = _square()
    edges = edge_pixels(depth, mask, jump=0.1)
    assert edges[3, 3] and edges[3, 5] and edges[2, 4] and edges[4, 2]  # the square's rim and the ring outside it
    assert not edges[4:6, 4:6].any()  # its inside
    assert not edges[2, 2] and not edges[0, 0]  # diagonal to the corner, far outside: no 4-neighbour differs
    ramp = np.where(mask, np.float32(1.0) + np.float32(0.05) * np.arange(10, dtype=np.float32)[None, :], np.inf)
    assert (edge_pixels(ramp, mask, jump=0.1) == edges).all()  # a 0.05 step a pixel is surface, not an edge
    step = depth.copy()
    step[3:7, 5:7] = 1.5  # the square's right half lies 0.5 further
    stepped = edge_pixels(step, mask, jump=0.1)
    assert stepped[4, 4] and stepped[4, 5] and not edges[4, 4]
    assert not edge_pixels(step, mask, jump=0.6)[4, 4]


def test_bands_follow_the_distance_to_the_nearest_edge_and_a_frame_without_edges_is_far():
    edges = np.zeros((1, 9), bool)
    edges[0, 0] = True
    assert list(bands(edges)[0]) == [BAND["edge"], *[BAND["near"]] * 2, *[BAND["mid"]] * 2, *[BAND["far"]] * 4]
    corner = np.zeros((5, 5), bool)
    corner[0, 0] = True
    band = bands(corner)  # Euclidean: (3, 2) is 3.61 px away (city block: 5, far); (3, 3) 4.24 px (chessboard: 3, mid)
    assert band[1, 1] == BAND["near"] and band[3, 2] == BAND["mid"] and band[3, 3] == BAND["far"]
    assert (bands(np.zeros((4, 4), bool)) == BAND["far"]).all()


def test_errors_land_in_the_band_of_their_pixels_and_the_figures_pool_them():
    n = 20
    ref_depth, ref_mask = _square(n, 2, 18)  # a 16 x 16 square: its centre is > 4 px from its rim
    depth, mask = ref_depth.copy(), ref_mask.copy()
    depth[10, 10] += 0.04  # far from the rim
    depth[2, 10] += 0.01  # on the rim
    mask[1, 10], depth[1, 10] = True, 1.0  # one pixel hit outside the square: a mask error on the edge ring
    counts = band_counts(depth, mask, ref_depth, ref_mask, jump=0.1)
    # inside the square the rings 1, 2, 3 ... from its rim lie 0, 1, 2 ... px from the nearest edge pixel (the rim)
    assert list(counts["pixels"]) == [60 + 1, 52 + 44, 36 + 28, 36]
    assert list(counts["both"]) == [60, 52 + 44, 36 + 28, 36]
    assert counts["mask_errors"][BAND["edge"]] == 1 and counts["mask_errors"].sum() == 1
    assert counts["abs_depth"][BAND["far"]] == pytest.approx(0.04, rel=1e-5)
    assert counts["abs_depth"][BAND["edge"]] == pytest.approx(0.01, rel=1e-4)
    fig = figures(counts)
    assert fig["pixels_near"] == pytest.approx(157 / 257) and fig["mask_errors_near"] == 1.0
    assert fig["depth_mae_near"] == pytest.approx(0.01 / 156, rel=1e-4)
    assert fig["abs_depth_near"] == pytest.approx(0.01 / 0.05, rel=1e-4)
    assert fig["depth_mae"] == pytest.approx(0.05 / 256, rel=1e-4)
    assert fig["mask_iou"] == pytest.approx(256 / 257)
    assert fig["depth_mae_far"] == pytest.approx(0.04 / 36, rel=1e-5)


def test_a_frame_pair_without_overlap_has_no_depth_figures():
    ref_depth, ref_mask = _square()
    empty = np.zeros_like(ref_mask)
    fig = figures(band_counts(np.full(ref_depth.shape, np.inf, np.float32), empty, ref_depth, ref_mask, jump=0.1))
    assert math.isnan(fig["depth_mae"]) and math.isnan(fig["depth_mae_far"]) and fig["mask_iou"] == 0.0
    nothing = np.full(ref_depth.shape, np.inf, np.float32)
    assert figures(band_counts(nothing, empty, nothing, empty, jump=0.1))["mask_iou"] == 1.0


RUN = ["model=grid_sdf", "model.resolution=24", "shape=sphere", "eval=smoke", "eval.n_points=2000",
       "eval.mesh_resolution=20", "scene=depth", "scene.width=32", "scene.height=32", "sampling=random",
       "sampling.n_samples=2000", "threads=1", "quiet=true"]


@pytest.mark.slow
def test_a_real_runs_pooled_figures_are_its_records_image_metrics_and_a_run_without_renders_is_named(tmp_path, capsys):
    done = subprocess.run([sys.executable, "-m", "ddfbench", *RUN, f"out_dir={tmp_path}"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    (rec,) = find_records(str(tmp_path / "single"))
    twin = os.path.join(os.path.dirname(rec["_dir"]), "twin")
    shutil.copytree(rec["_dir"], twin)
    renders = os.path.join(twin, rec["artifacts"]["renders"])
    for name in os.listdir(renders):
        if "_mask" in name:
            os.remove(os.path.join(renders, name))  # as a scene without the mask output would leave it
    with open(os.path.join(twin, "record.json"), "w") as fh:
        json.dump({**{k: v for k, v in rec.items() if k != "_dir"}, "key": "twin"}, fh)
    assert main([str(tmp_path / "single"), "--out", str(tmp_path / "edges")]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("ddfbench.report.edge_error")]
    assert len(err) == 1 and twin in err[0] and "cam0_mask.npy: missing" in err[0]
    table = pd.read_csv(tmp_path / "edges" / "table.csv")
    assert set(table["key"]) == {rec["key"]} and list(table["band"]) == [name for name, _ in BANDS]
    row = table.iloc[0]
    assert row["depth_mae"] == pytest.approx(rec["metrics"]["depth_mae"], rel=1e-5)
    assert row["mask_iou"] == pytest.approx(rec["metrics"]["mask_iou"], rel=1e-9)
    assert table["pixels"].sum() > 0 and 0 < row["pixels_near"] < 1
    assert "1 runs' saved renders (1 unreadable)" in (tmp_path / "edges" / "table.md").read_text()
    assert rebuilt_differences(tmp_path / "edges", tmp_path / "edges_again") == []  # from its measured rows alone


def test_a_bad_jump_and_a_folder_without_records_are_one_line_errors(tmp_path, capsys):
    assert main([str(tmp_path), "--out", str(tmp_path / "o"), "--jump", "0"]) == 2
    assert main([str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("ddfbench.report.edge_error: --jump 0") and "no finished run records" in err[1]
    assert not (tmp_path / "o").exists()


def test_the_table_pools_seeds_and_says_where_fewer_runs_define_a_figure():
    from ddfbench.report.edge_error import COLUMNS, to_markdown

    run = {key: 0.5 for key, _, _ in COLUMNS}
    runs = pd.DataFrame([{"model": "m", "shape": "s", "capacity": "c1", **run, "depth_mae_far": math.nan, "no_result": False},
                         {"model": "m", "shape": "s", "capacity": "c1", **run, "depth_mae_far": 0.002, "no_result": False},
                         {"model": "m", "shape": "s", "capacity": "c2", **run, "no_result": True}])
    table = to_markdown(runs).splitlines()
    assert next(line for line in table if line.startswith("| m | s | c2 |")).split("|")[4].strip() == "1 not converged"
    row = next(line for line in table if line.startswith("| m | s | c1 |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[3] == "2"  # n: the runs of the row
    assert cells[4] == "50 ± 0 [50, 50]"  # two identical runs: no spread
    assert cells[4 + [key for key, _, _ in COLUMNS].index("depth_mae_far")] == "2 (n = 1)"


def test_a_run_with_a_cameras_renders_lost_is_named_not_measured_in_part(tmp_path):
    from ddfbench.core.errors import InputError
    from ddfbench.report.edge_error import run_counts

    (tmp_path / "renders").mkdir()
    for name in ("cam0_depth_reference.npy", "cam0_depth.npy"):
        (tmp_path / "renders" / name).write_bytes(b"")
    rec = {"_dir": str(tmp_path), "artifacts": {"renders": "renders"}, "config": {"scene": {"cameras": {"n": 2}}}}
    with pytest.raises(InputError, match=r"renders: depth renders of 1 of the scene's 2 cameras$"):
        run_counts(rec, 0.05)
