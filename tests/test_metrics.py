"""Metrics against brute force on small clouds, plus penalties and the noise floor."""

import numpy as np
import trimesh

from ddfbench.evaluate import metrics
from ddfbench.evaluate.metric_registry import PENALTY_DISTANCE


def pairwise_sq(a, b):
    """Squared distances (N, M) between every point of a (N,3) and of b (M,3)."""
    return ((a[:, None, :] - b[None, :, :]) ** 2).sum(-1)


def brute_sq(a, b):
    """Squared distance (N,) from each point of a to its nearest point of b, over all pairs."""
    return pairwise_sq(a, b).min(axis=1)


def brute_fscore(gt, rec, r):
    """F-score at radius r over all pairs: precision = share of rec within r of gt, recall the reverse."""
    p, rc = (np.sqrt(brute_sq(rec, gt)) <= r).mean(), (np.sqrt(brute_sq(gt, rec)) <= r).mean()
    return 0.0 if p + rc == 0 else 2 * p * rc / (p + rc)


def test_cloud_metrics_match_brute_force(rng):
    gt, rec = rng.normal(size=(300, 3)), rng.normal(size=(200, 3)) + 0.1
    m = metrics.cloud_metrics(gt, rec, [0.1])
    assert np.isclose(m["chamfer_l2"], brute_sq(gt, rec).mean() + brute_sq(rec, gt).mean())
    assert np.isclose(m["chamfer_l1"], 0.5 * (np.sqrt(brute_sq(gt, rec)).mean() + np.sqrt(brute_sq(rec, gt)).mean()))
    to_rec = brute_sq(gt, rec)
    assert np.isclose(m["sided_gt_to_rec"]["mean"], to_rec.mean())
    assert np.isclose(m["sided_gt_to_rec"]["median"], np.median(to_rec))
    assert np.isclose(m["sided_gt_to_rec"]["p95"], np.percentile(to_rec, 95))
    assert np.isclose(m["sided_rec_to_gt"]["mean"], brute_sq(rec, gt).mean())


def test_fscore_matches_brute_force(rng):
    gt, pred = rng.uniform(size=(250, 3)), rng.uniform(size=(180, 3))
    r = 0.08
    fscore = lambda a, b: metrics.cloud_metrics(a, b, [r])["fscore"][str(r)]  # noqa: E731
    assert 0 < brute_fscore(gt, pred, r) < 1 and np.isclose(fscore(gt, pred), brute_fscore(gt, pred, r))
    assert fscore(gt, gt + 10.0) == 0.0
    assert fscore(gt, gt) == 1.0


def test_chamfer_is_symmetric_and_zero_on_identity(rng):
    a, b = rng.normal(size=(100, 3)), rng.normal(size=(120, 3))
    ab, ba, aa = (metrics.cloud_metrics(x, y, []) for x, y in ((a, b), (b, a), (a, a)))
    assert np.isclose(ab["chamfer_l2"], ba["chamfer_l2"]) and np.isclose(ab["chamfer_l1"], ba["chamfer_l1"])
    assert aa["chamfer_l2"] == 0.0 and aa["chamfer_l1"] == 0.0


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


def test_level_offset_is_signed_shift_of_the_surface():
    """A sphere inflated by 0.05 is 0.05 outside GT on average, a deflated one 0.05 inside; GT against
    itself and a surface noisy on both sides sit near 0 while their p2s chamfer does not."""
    sphere = trimesh.creation.icosphere(4, 0.5)
    assert abs(metrics.geometry_metrics(sphere, sphere, 5000, [0.01], seed=0)["level_offset"]) < 1e-6
    for radius, offset in ((0.55, 0.05), (0.45, -0.05)):
        m = metrics.geometry_metrics(sphere, trimesh.creation.icosphere(4, radius), 5000, [0.01], seed=0)
        assert np.isclose(m["level_offset"], offset, rtol=0.05)
    bumpy = sphere.copy()
    bumpy.vertices *= 1 + np.random.default_rng(0).uniform(-0.1, 0.1, (len(bumpy.vertices), 1))  # out and in
    m = metrics.geometry_metrics(sphere, bumpy, 5000, [0.01], seed=0)
    assert abs(m["level_offset"]) < 0.2 * m["p2s_chamfer_l1"]


def test_empty_reconstruction_gets_penalty_not_exception():
    sphere = trimesh.creation.icosphere(3, 0.5)
    empty = trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), int))
    m = metrics.geometry_metrics(sphere, empty, 1000, [0.01], seed=0)
    assert m["empty_reconstruction"] is True
    assert m["fscore"]["0.01"] == 0.0
    assert np.isfinite(m["chamfer_l2"]) and m["chamfer_l2"] >= PENALTY_DISTANCE**2
    assert m["closed"] == 0.0 and "components" not in m  # no piece count for an empty mesh: left out of means
    assert "level_offset" not in m  # nor an offset: an empty mesh has no points to be inside or outside


def test_topology_counts_pieces_and_finds_holes():
    sphere = trimesh.creation.icosphere(2, 0.3)
    far = sphere.copy().apply_translation((0.7, 0, 0))
    assert metrics.topology(sphere) == {"closed": True, "components": 1}
    assert metrics.topology(trimesh.util.concatenate([sphere, far])) == {"closed": True, "components": 2}
    box = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    corner_to_corner = trimesh.util.concatenate([box, box.copy().apply_translation((0.2, 0.2, 0.2))])
    assert metrics.topology(corner_to_corner) == {"closed": True, "components": 2}  # one shared vertex, no edge
    edge_to_edge = trimesh.util.concatenate([box, box.copy().apply_translation((0.2, 0.2, 0))])
    assert metrics.topology(edge_to_edge) == {"closed": False, "components": 1}  # a 4-face edge joins them
    doubled = trimesh.Trimesh(box.vertices, np.vstack([box.faces, box.faces[:1]]), process=False)
    assert metrics.topology(doubled) == {"closed": False, "components": 1}  # its 3-face edges join the copy
    sliver = trimesh.Trimesh(box.vertices, np.vstack([box.faces, [[0, 0, 1]]]), process=False)
    assert metrics.topology(sliver) == {"closed": True, "components": 1}  # a repeated-vertex face is dropped
    assert metrics.topology(trimesh.Trimesh(box.vertices, [[0, 0, 1]], process=False))["components"] == 0
    holed = trimesh.Trimesh(sphere.vertices, sphere.faces[1:], process=False)
    assert metrics.topology(holed) == {"closed": False, "components": 1}
    # a triangle soup (every face its own three vertices) is the same closed surface once merged
    soup = trimesh.Trimesh(sphere.vertices[sphere.faces].reshape(-1, 3),
                           np.arange(3 * len(sphere.faces)).reshape(-1, 3), process=False)
    assert not soup.is_watertight and metrics.topology(soup) == {"closed": True, "components": 1}
    # geometry_metrics records it for a reconstruction
    m = metrics.geometry_metrics(sphere, holed, 1000, [0.01], seed=0, with_point_to_surface=False)
    assert m["closed"] is False and m["components"] == 1


def test_geometry_metrics_equal_brute_force_on_its_own_samples():
    """geometry_metrics shares KD-trees between metrics; each value must equal an all-pairs computation
    on the same seeded samples (GT seed, rec seed + 1, floor seed + 2)."""
    gt, rec = trimesh.creation.icosphere(3, 0.5), trimesh.creation.box(extents=(0.8, 0.9, 1.0))
    m = metrics.geometry_metrics(gt, rec, 1000, [0.01, 0.05], seed=4, with_point_to_surface=False)
    g, gn = metrics.sample_surface(gt, 1000, 4)
    r, rn = metrics.sample_surface(rec, 1000, 5)
    floor = metrics.sample_surface(gt, 1000, 6)[0]
    sq = pairwise_sq(g, r)
    d_gr, d_rg = np.sqrt(sq.min(1)), np.sqrt(sq.min(0))
    assert np.isclose(m["chamfer_l2"], (d_gr**2).mean() + (d_rg**2).mean())
    assert np.isclose(m["chamfer_l1"], 0.5 * (d_gr.mean() + d_rg.mean()))
    assert all(np.isclose(m["fscore"][str(t)], brute_fscore(g, r, t)) for t in (0.01, 0.05))
    assert np.isclose(m["sided_rec_to_gt"]["mean"], (d_rg**2).mean())
    cos_gr = np.abs((gn * rn[sq.argmin(1)]).sum(1))
    cos_rg = np.abs((rn * gn[sq.argmin(0)]).sum(1))
    assert 0.5 < m["normal_consistency"] < 1 and np.isclose(m["normal_consistency"], 0.5 * (cos_gr.mean() + cos_rg.mean()))
    assert np.isclose(m["noise_floor"]["chamfer_l2"], brute_sq(g, floor).mean() + brute_sq(floor, g).mean())


def test_empty_reconstruction_scores_the_radii_a_run_measures():
    """An empty reconstruction's F-score penalties sit at the run's radii only, as a non-empty run's F-scores
    do: a registry radius the config did not ask for would give a table column a 0 no run measured."""
    sphere = trimesh.creation.icosphere(3, 0.5)
    empty = trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), int))
    full = metrics.geometry_metrics(sphere, sphere, 1000, [0.05], seed=0, with_point_to_surface=False)
    none = metrics.geometry_metrics(sphere, empty, 1000, [0.05], seed=0, with_point_to_surface=False)
    assert set(none["fscore"]) == set(full["fscore"]) == {"0.05"} and none["fscore"]["0.05"] == 0.0


def test_normal_consistency_ignores_orientation():
    """Normal consistency is the unsigned cosine: a reconstruction wound inside out (every normal flipped, as
    marching cubes on a negated field gives) scores the same as the same surface wound outward, both near 1.
    Kills dropping either np.abs in matched_normal_consistency (the flipped mesh would score near -1 or 0)."""
    sphere = trimesh.creation.icosphere(4, 0.5)
    flipped = trimesh.Trimesh(sphere.vertices, sphere.faces[:, ::-1], process=False)
    same = metrics.geometry_metrics(sphere, sphere, 2000, [0.01], seed=0, noise_floor=False,
                                    with_point_to_surface=False)
    inside_out = metrics.geometry_metrics(sphere, flipped, 2000, [0.01], seed=0, noise_floor=False,
                                          with_point_to_surface=False)
    assert same["normal_consistency"] > 0.95
    assert np.isclose(inside_out["normal_consistency"], same["normal_consistency"])


def test_the_evaluation_points_are_a_stream_apart_from_the_samplers_face_draws():
    """The surface sampler draws its area-weighted faces from default_rng(run seed); GT points drawn from that
    seed too lie on the same faces (every one of them at s_fc = 1, where the chance share is 1 - 1/e). The
    evaluation's stream of its own puts about the chance share on faces training drew, for every run seed."""
    from ddfbench.report.reevaluate import record_evaluation_seed
    from ddfbench.sampling.triangles import face_plan

    mesh = trimesh.creation.icosphere(3, 0.4)
    mesh = trimesh.Trimesh(mesh.vertices * [1.0, 0.6, 0.3], mesh.faces, process=False)  # unequal face areas
    normal_key = {tuple(np.round(n, 6)): i for i, n in enumerate(mesh.face_normals)}

    def drawn_share(eval_seed, run_seed):
        trained = set(face_plan(mesh, 1, "total", np.random.default_rng(run_seed)).tolist())
        _, normals = metrics.sample_surface(mesh, len(mesh.faces), eval_seed)
        return np.mean([normal_key[tuple(np.round(n, 6))] in trained for n in normals])

    assert drawn_share(5, 5) == 1.0  # the shared stream (records before 1.7.0)
    shares = [drawn_share(metrics.evaluation_seed(s), s) for s in range(4)]
    assert all(abs(share - (1 - 1 / np.e)) < 0.06 for share in shares), shares
    assert len({metrics.evaluation_seed(s) for s in range(1000)}) == 1000
    assert record_evaluation_seed({"config": {"seed": 3}}) == 3  # a record before 1.7.0: the run's seed
    assert record_evaluation_seed({"config": {"seed": 3}, "metrics": {"eval_seed": 17}}) == 17
