"""Case 12: empty and single-point reconstructions in every metric.

Promise: geometry_metrics gives the documented penalty (chamfer L2 = 2 D^2, chamfer L1 = D, f-scores 0,
D = the domain diagonal 2*0.6*sqrt(3)) and empty_reconstruction = True for a reconstruction with no
faces, no area or non-finite vertices, and the runner adds the flag to the record. Every point-cloud
metric, given an empty cloud, returns that same penalty instead of NaN, inf or an exception; a
single point or a single triangle gives finite values.
"""

import numpy as np
import pytest
import trimesh

from ddfbench.evaluate import metrics
from ddfbench.evaluate.extract import empty_mesh
from ddfbench.truth.shapes import load_shape

RADII = [0.005, 0.01, 0.02]
D = 2 * 0.6 * np.sqrt(3.0)


@pytest.fixture(scope="module")
def gt():
    return load_shape({"name": "bone"}).mesh


def degenerate_reconstructions():
    v = np.array([[0.0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]])
    return {
        "no faces": empty_mesh(),
        "zero area": trimesh.Trimesh(v, [[0, 1, 2]], process=False),
        "nan vertices": trimesh.Trimesh(np.full((3, 3), np.nan), [[0, 1, 2]], process=False),
    }


@pytest.mark.parametrize("kind", list(degenerate_reconstructions()))
def test_empty_reconstruction_gets_the_penalty(gt, kind):
    m = metrics.geometry_metrics(gt, degenerate_reconstructions()[kind], 2000, RADII, seed=0)
    assert m["empty_reconstruction"] is True
    assert m["chamfer_l2"] == pytest.approx(2 * D**2) and m["chamfer_l1"] == pytest.approx(D)
    assert all(v == 0.0 for v in m["fscore"].values())
    assert all(np.isfinite(v) for v in (m["sided_gt_to_rec"]["mean"], m["sided_rec_to_gt"]["p95"]))


def test_single_triangle_reconstruction_is_finite(gt):
    tiny = trimesh.Trimesh([[0.0, 0, 0], [1e-3, 0, 0], [0, 1e-3, 0]], [[0, 1, 2]], process=False)
    m = metrics.geometry_metrics(gt, tiny, 2000, RADII, seed=0)
    assert m["empty_reconstruction"] is False
    assert 0 < m["chamfer_l2"] < 2 * D**2 and np.isfinite(m["p2s_chamfer_l2"])
    assert all(0.0 <= v <= 1.0 for v in m["fscore"].values())


def test_single_point_cloud_is_finite(gt):
    a = metrics.sample_surface(gt, 500, 0)[0]
    m = metrics.cloud_metrics(a, np.zeros((1, 3)), RADII)
    assert np.isfinite(m["chamfer_l2"]) and np.isfinite(m["chamfer_l1"]) and np.isfinite(m["sided_rec_to_gt"]["mean"])
    assert all(0.0 <= v <= 1.0 for v in m["fscore"].values())


@pytest.mark.parametrize("empty_side", ["rec", "gt"])
def test_empty_point_cloud_gets_the_penalty(gt, empty_side):
    """Every cloud metric of an empty (0, 3) cloud, on either side, is its finite penalty (penalty_metrics),
    not inf or NaN: chamfer distances as if every point were the box diagonal D away, f-scores 0."""
    a, empty = metrics.sample_surface(gt, 500, 0)[0], np.zeros((0, 3))
    m = metrics.cloud_metrics(a, empty, RADII) if empty_side == "rec" else metrics.cloud_metrics(empty, a, RADII)
    assert m["chamfer_l2"] == pytest.approx(2 * D**2) and m["chamfer_l1"] == pytest.approx(D)
    assert all(v == 0.0 for v in m["fscore"].values()) and m["empty_reconstruction"] is True
    assert m["sided_gt_to_rec"]["mean"] == pytest.approx(D**2)


def test_runner_flags_an_empty_reconstruction(tmp_path, monkeypatch):
    from ddfbench.models.mesh import MeshFamily
    from ddfbench.run.runner import run
    from tests.hard_cases.conftest import compose

    monkeypatch.setattr(MeshFamily, "to_mesh", lambda self, resolution: empty_mesh())
    rec = run(compose("shape=cube", "model=mesh", out_dir=tmp_path))
    assert rec["status"] == "ok" and "empty_reconstruction" in rec["flags"]
    assert rec["metrics"]["chamfer_l2"] == pytest.approx(2 * D**2)
