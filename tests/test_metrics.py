"""Metrics against brute force on small clouds, plus penalties and the noise floor."""

import numpy as np
import trimesh

from ddfbench import metrics


def brute_sq(a, b):
    return ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1).min(axis=1)


def test_sided_and_chamfer_match_brute_force(rng):
    a, b = rng.normal(size=(300, 3)), rng.normal(size=(200, 3)) + 0.1
    assert np.allclose(metrics.sided_distance(a, b), brute_sq(a, b))
    expect = 0.5 * brute_sq(a, b).mean() + 2.0 * brute_sq(b, a).mean()
    assert np.isclose(metrics.chamfer_distance(a, b, w1=0.5, w2=2.0), expect)
    expect_l1 = 0.5 * (np.sqrt(brute_sq(a, b)).mean() + np.sqrt(brute_sq(b, a)).mean())
    assert np.isclose(metrics.chamfer_l1(a, b), expect_l1)


def test_fscore_matches_brute_force(rng):
    gt, pred = rng.uniform(size=(250, 3)), rng.uniform(size=(180, 3))
    r = 0.08
    p = (np.sqrt(brute_sq(pred, gt)) <= r).mean()
    rc = (np.sqrt(brute_sq(gt, pred)) <= r).mean()
    assert np.isclose(metrics.f_score(gt, pred, r), 2 * p * rc / (p + rc))
    assert metrics.f_score(gt, gt + 10.0, r) == 0.0
    assert metrics.f_score(gt, gt, r) == 1.0


def test_chamfer_is_symmetric_and_zero_on_identity(rng):
    a, b = rng.normal(size=(100, 3)), rng.normal(size=(120, 3))
    assert np.isclose(metrics.chamfer_distance(a, b), metrics.chamfer_distance(b, a))
    assert metrics.chamfer_distance(a, a) == 0.0


def test_sample_surface_lies_on_mesh_and_is_seeded():
    box = trimesh.creation.box(extents=(1, 2, 3))
    p, n = metrics.sample_surface(box, 2000, seed=3)
    on_face = np.isclose(np.abs(p), [0.5, 1.0, 1.5], atol=1e-9).any(axis=1)
    assert on_face.all()
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    assert np.array_equal(p, metrics.sample_surface(box, 2000, seed=3)[0])
    # area weighting: faces normal to z (area 2 each) vs x (area 6 each)
    share_z = np.isclose(np.abs(p[:, 2]), 1.5).mean()
    assert abs(share_z - 2 * 2 / 22) < 0.04


def test_geometry_metrics_noise_floor_and_point_to_surface():
    sphere = trimesh.creation.icosphere(4, 0.5)
    m = metrics.geometry_metrics(sphere, sphere, 5000, [0.01, 0.02], seed=0)
    assert not m["empty_reconstruction"]
    floor = m["noise_floor"]["chamfer_l2"]
    assert floor > 0
    # the same surface measured by independent samples sits at the noise floor
    assert 0.5 < m["chamfer_l2"] / floor < 2.0
    # point-to-surface of a surface against itself has no sampling floor
    assert m["p2s_chamfer_l2"] < 1e-10
    bigger = trimesh.creation.icosphere(4, 0.55)
    m2 = metrics.geometry_metrics(sphere, bigger, 5000, [0.01, 0.02], seed=0)
    assert np.isclose(m2["p2s_chamfer_l1"], 0.05, rtol=0.05)
    assert m2["fscore"]["0.01"] < 0.05 and m2["fscore"]["0.02"] < 0.05


def test_empty_reconstruction_gets_penalty_not_exception():
    sphere = trimesh.creation.icosphere(3, 0.5)
    empty = trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), int))
    m = metrics.geometry_metrics(sphere, empty, 1000, [0.01], seed=0)
    assert m["empty_reconstruction"] is True
    assert m["fscore"]["0.01"] == 0.0
    assert np.isfinite(m["chamfer_l2"]) and m["chamfer_l2"] >= metrics.PENALTY_DISTANCE**2


def test_geometry_metrics_equal_the_metrics_on_its_own_samples():
    """geometry_metrics shares KD-trees between metrics; each value must equal the standalone metric."""
    gt, rec = trimesh.creation.icosphere(3, 0.5), trimesh.creation.box(extents=(0.8, 0.9, 1.0))
    m = metrics.geometry_metrics(gt, rec, 3000, [0.01, 0.05], seed=4, with_point_to_surface=False)
    g, gn = metrics.sample_surface(gt, 3000, 4)
    r, rn = metrics.sample_surface(rec, 3000, 5)
    floor = metrics.sample_surface(gt, 3000, 6)[0]
    assert np.isclose(m["chamfer_l2"], brute_sq(g, r).mean() + brute_sq(r, g).mean())
    assert np.isclose(m["chamfer_l1"], metrics.chamfer_l1(g, r))
    assert all(np.isclose(m["fscore"][str(t)], metrics.f_score(g, r, t)) for t in (0.01, 0.05))
    assert np.isclose(m["sided_rec_to_gt"]["mean"], brute_sq(r, g).mean())
    assert np.isclose(m["normal_consistency"], metrics.normal_consistency(g, gn, r, rn))
    assert np.isclose(m["noise_floor"]["chamfer_l2"], brute_sq(g, floor).mean() + brute_sq(floor, g).mean())
