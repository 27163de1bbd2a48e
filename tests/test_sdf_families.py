"""SDF-like families (grid_sdf, neural_sdf, gan_sdf) and the level-set grid build.

References: the analytic sphere (|x| - r), brute-force oracle grids, analytic fast-sweeping solutions.
"""

import os

import numpy as np
import pytest
import torch

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import grid_points
from ddfbench.core.representation import Budget, FitData, RayStatus
from ddfbench.models import load_family
from ddfbench.models.neural_sdf import clamped_l1
from ddfbench.sampling.oracle_sdf import oracle_sdf_samples
from ddfbench.truth import levelset
from ddfbench.truth.oracle import Oracle
from ddfbench.truth.shapes import load_shape

RADIUS = 0.5  # the catalog sphere, normalized: an icosphere of radius 0.5 (faceted: gaps below 4e-4)
DOMAIN = 0.6


@pytest.fixture(scope="module", autouse=True)
def _few_threads():
    old = torch.get_num_threads()
    torch.set_num_threads(1)  # the test machine is shared: more threads only wait on each other
    yield
    torch.set_num_threads(old)


@pytest.fixture(scope="module")
def sphere():
    shape = load_shape({"name": "sphere"})
    oracle = Oracle(shape.mesh)
    return shape.mesh, oracle, oracle_sdf_samples(shape.mesh, oracle, 20000, seed=0)


def near_points(n=2000, seed=1, band=0.1):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return (d * (RADIUS + rng.uniform(-band, band, (n, 1)))).astype(np.float32)


def rays_at_sphere(n=400, seed=2):
    rng = np.random.default_rng(seed)
    o = rng.normal(size=(n, 3))
    o = o / np.linalg.norm(o, axis=1, keepdims=True) * 1.2
    d = rng.normal(size=(n, 3)) * 0.15 - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    b = (o * d).sum(1)
    disc = b * b - ((o * o).sum(1) - RADIUS**2)
    t = np.where(disc > 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
    return o.astype(np.float32), d.astype(np.float32), t, disc


def check_round_trip(rep, tmp_path, family):
    """save -> load gives identical sdf and intersect outputs; storage_bytes is the saved file's size."""
    path = rep.save(str(tmp_path / "model"))
    assert rep.storage_bytes() == os.path.getsize(path)
    again = load_family(family).load(path)
    assert again.storage_bytes() == os.path.getsize(path)
    assert again.n_params() == rep.n_params()
    p = near_points(500, seed=9)
    assert np.array_equal(rep.sdf(p), again.sdf(p))
    o, d, _, _ = rays_at_sphere(100, seed=10)
    a, b = rep.intersect(o, d), again.intersect(o, d)
    assert np.array_equal(a.t, b.t) and np.array_equal(a.normal, b.normal) and np.array_equal(a.status, b.status)
    return path


def check_rays(rep, depth_tol, normal_tol_deg):
    """intersect against the analytic sphere: hits, depth, normals facing the ray, stats."""
    o, d, t_ref, disc = rays_at_sphere()
    hits = rep.intersect(o, d)
    clear = disc > 0.05
    assert hits.hit[clear & np.isfinite(t_ref)].all()
    assert not hits.hit[disc < -0.05].any()
    both = clear & hits.hit
    assert np.abs(hits.t[both] - t_ref[both]).max() < depth_tol
    p = o[both] + hits.t[both, None] * d[both]
    exact = p / np.linalg.norm(p, axis=1, keepdims=True)
    cos = np.einsum("ij,ij->i", hits.normal[both], exact)
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < normal_tol_deg
    assert (np.einsum("ij,ij->i", hits.normal[hits.hit], d[hits.hit]) < 0).all()
    for key in ("field_evals", "trace_steps", "backward_passes"):
        assert key in hits.stats
    assert hits.stats["field_evals"] >= hits.stats["trace_steps"] + int(hits.hit.sum())
    no_normals = rep.intersect(o, d, normals=False)
    assert np.array_equal(no_normals.t, hits.t) and no_normals.stats["backward_passes"] == 0
    return hits


# ---- level-set grid build ----------------------------------------------------------------------
def test_fast_sweep_is_exact_for_a_plane_and_first_order_for_a_sphere():
    n, h = 33, 1.0 / 32
    x = np.arange(n) * h
    X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
    plane = np.abs(X - 0.3)
    frozen = plane <= 2 * h
    u, _ = levelset.fast_sweep(np.where(frozen, plane, np.inf).astype(np.float32), frozen, h)
    assert np.abs(u - plane).max() < 1e-5
    mean_err = []
    for n in (33, 65):
        h = 1.0 / (n - 1)
        x = np.arange(n) * h
        X, Y, Z = np.meshgrid(x, x, x, indexing="ij")
        ball = np.abs(np.sqrt((X - 0.5) ** 2 + (Y - 0.5) ** 2 + (Z - 0.5) ** 2) - 0.25)
        frozen = ball <= 2 * h
        u, rounds = levelset.fast_sweep(np.where(frozen, ball, np.inf).astype(np.float32), frozen, h, rounds=3)
        err = np.abs(u - ball)
        assert rounds == 2  # one round of 8 sweeps converges; the second changes nothing
        assert err.max() < 1.25 * h and np.all(err[ball < 0.1] < 0.25 * h)  # worst at the centre (medial axis)
        mean_err.append(err.mean())
    assert 0 < mean_err[1] < 0.65 * mean_err[0]  # first order: halving h about halves the error


def test_levelset_grid_matches_brute_force():
    shape = load_shape({"name": "cow"})
    oracle = Oracle(shape.mesh)
    n = 40
    h = 2 * DOMAIN / (n - 1)
    exact = levelset.exact_sdf_grid(oracle, n, DOMAIN)
    grid, info = levelset.levelset_sdf_grid(oracle, n, DOMAIN, band_cells=2.0)
    band = np.abs(exact) <= 2 * h
    assert info["exact_nodes"] >= band.sum() and info["exact_nodes"] < 0.5 * n**3  # band only, all of it
    assert np.abs(np.abs(grid[band]) - np.abs(exact[band])).max() < 1e-6
    assert (np.sign(grid) != np.sign(exact)).mean() < 1e-3  # voted inside tests may differ on a rare node
    assert np.abs(np.abs(grid) - np.abs(exact)).max() < 1.5 * h


def test_component_signs_fall_back_when_votes_disagree():
    # an open box: inside and outside connect through the missing face, so one component has both
    shape = load_shape({"name": "open_box"})
    oracle = Oracle(shape.mesh)
    n = 24
    dist, queried = levelset.narrow_band(oracle, n, DOMAIN, 2 * 2 * DOMAIN / (n - 1))
    inside, queries = levelset.component_signs(oracle, queried, n, DOMAIN, votes=9)
    pts = grid_points(n, DOMAIN)
    assert queries > queried.sum() + 9 * 2  # the node-by-node fallback ran on a mixed component
    deep = (np.abs(pts[:, :2]).max(1) < 0.3) & (np.abs(pts[:, 2] + 0.25) < 0.1)  # far below the opening
    outside = (np.abs(pts[:, :2]).max(1) > 0.55) & (pts[:, 2] < 0)  # beside the box, away from the opening
    assert inside.reshape(-1)[deep].mean() > 0.9 and inside.reshape(-1)[outside].mean() < 0.1  # votes are random rays


# ---- grid_sdf ----------------------------------------------------------------------------------
@pytest.mark.parametrize("build", ["exact", "levelset"])
def test_grid_sdf_fits_the_sphere(sphere, build, tmp_path):
    mesh, oracle, _ = sphere
    rep = load_family("grid_sdf")({"resolution": 40, "build": build}, DOMAIN)
    stats = rep.fit(FitData(None, mesh, oracle), Budget())
    assert stats.status == "ok" and stats.extra["build"] == build
    p = near_points()
    h = 2 * DOMAIN / 39
    assert np.abs(rep.sdf(p) - (np.linalg.norm(p, axis=1) - RADIUS)).max() < 0.1 * h + 1e-3
    far = np.array([[1.0, 0.0, 0.0], [0.0, -2.0, 0.0]], np.float32)  # outside the box: value + distance to box
    assert np.allclose(rep.sdf(far), np.linalg.norm(far, axis=1) - RADIUS, atol=2e-3)
    hits = check_rays(rep, depth_tol=2e-3, normal_tol_deg=3.0)
    assert hits.stats["backward_passes"] == 0
    assert hits.stats["field_evals"] >= hits.stats["trace_steps"] + 6 * int(hits.hit.sum())
    m = rep.to_mesh(32)
    assert len(m.faces) > 0 and np.abs(np.linalg.norm(m.vertices, axis=1) - RADIUS).max() < 0.01
    assert rep.n_params() == 40**3
    check_round_trip(rep, tmp_path, "grid_sdf")


def test_grid_sdf_float16_storage_is_half(sphere, tmp_path):
    mesh, oracle, _ = sphere
    sizes = {}
    for dtype in ("float32", "float16"):
        rep = load_family("grid_sdf")({"resolution": 24, "dtype": dtype}, DOMAIN)
        rep.fit(FitData(None, mesh, oracle), Budget())
        os.makedirs(tmp_path / dtype)
        check_round_trip(rep, tmp_path / dtype, "grid_sdf")
        sizes[dtype] = rep.storage_bytes()
        assert np.abs(rep.sdf(near_points()) - (np.linalg.norm(near_points(), axis=1) - RADIUS)).max() < 0.01
    assert 24**3 * 2 <= sizes["float16"] < 0.6 * sizes["float32"]


def test_grid_sdf_bad_input():
    with pytest.raises(InputError, match="dtype"):
        load_family("grid_sdf")({"dtype": "int8"})
    with pytest.raises(InputError, match="build"):
        load_family("grid_sdf")({"build": "magic"})


def test_grid_sdf_corrupt_artifact(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip file")
    with pytest.raises(InputError, match="bad.npz"):
        load_family("grid_sdf").load(str(bad))


# ---- neural_sdf --------------------------------------------------------------------------------
SMALL_NET = {"width": 32, "depth": 3, "n_harmonics": 2, "batch": 2048, "lr": 3e-3, "lr_schedule": "cosine"}


def test_neural_sdf_geometric_init_is_a_sphere():
    # exact in the wide relu limit (SAL); a wide relu net is already close
    torch.manual_seed(0)
    rep = load_family("neural_sdf")({"init_radius": 0.3, "activation": "relu", "width": 1024, "depth": 2})
    p = near_points(1000, band=0.2)
    ref = np.linalg.norm(p, axis=1) - 0.3
    assert np.abs(rep.sdf(p) - ref).mean() < 0.03
    plain = load_family("neural_sdf")({"geometric_init": False, "activation": "relu", "width": 1024, "depth": 2})
    assert np.abs(plain.sdf(p) - ref).mean() > 0.1


@pytest.mark.slow
def test_neural_sdf_fits_the_sphere(sphere, tmp_path):
    mesh, oracle, samples = sphere
    rep = load_family("neural_sdf")({**SMALL_NET, "w_eikonal": 0.05}, DOMAIN)
    probes = []
    stats = rep.fit(FitData(samples, mesh, oracle), Budget(max_steps=600, max_seconds=60, n_probes=3),
                    probe=lambda r: probes.append(1) or {"n": float(len(probes))})
    assert stats.status == "ok" and stats.steps == 600 and len(stats.probes) == 3
    p = near_points()
    assert np.abs(rep.sdf(p) - (np.linalg.norm(p, axis=1) - RADIUS)).mean() < 0.005
    hits = check_rays(rep, depth_tol=0.01, normal_tol_deg=10.0)
    assert hits.stats["backward_passes"] == int(hits.hit.sum())
    m = rep.to_mesh(32)
    assert len(m.faces) > 0 and np.abs(np.linalg.norm(m.vertices, axis=1) - RADIUS).mean() < 0.005
    check_round_trip(rep, tmp_path, "neural_sdf")


def test_clamped_l1_is_deepsdf_in_the_band_and_pulls_back_an_overshoot():
    delta = 0.1
    target = torch.tensor([0.05, 0.05, 0.3, 0.3, -0.02])
    pred = torch.tensor([0.02, 0.7, 0.5, -0.4, 0.2], requires_grad=True)
    per_point = [float(clamped_l1(pred.detach()[i : i + 1], target[i : i + 1], delta)) for i in range(5)]
    # in the band: DeepSDF's |f - s|; past the target's own bound: 0; past the band elsewhere: |f - clamp(s)|
    assert np.allclose(per_point, [0.03, 0.65, 0.0, 0.5, 0.22])
    (grad,) = torch.autograd.grad(clamped_l1(pred, target, delta), pred)
    assert grad[1] > 0 and grad[2] == 0 and grad[3] < 0 and grad[4] > 0  # DeepSDF's is 0 at 1, 3 and 4


def test_neural_sdf_nan_guard_fires_on_divergence(sphere):
    mesh, oracle, samples = sphere
    rep = load_family("neural_sdf")({**SMALL_NET, "lr": 1e30, "activation": "relu"}, DOMAIN)
    stats = rep.fit(FitData(samples, mesh, oracle), Budget(max_steps=200, max_seconds=30))
    assert stats.status == "failed" and "non-finite" in stats.message
    # a failed model still answers without raising: no hit is invented, the mesh is flagged empty
    o, d, _, _ = rays_at_sphere(50)
    hits = rep.intersect(o, d)
    assert not hits.hit.any() and (hits.status != RayStatus.HIT).all()
    assert len(rep.to_mesh(16).faces) == 0 and rep.extract_info["empty"]


def test_neural_sdf_needs_sdf_samples(sphere):
    mesh, oracle, _ = sphere
    with pytest.raises(InputError, match="SDF samples"):
        load_family("neural_sdf")(SMALL_NET).fit(FitData(None, mesh, oracle), Budget(max_steps=1))
    with pytest.raises(InputError, match="activation"):
        load_family("neural_sdf")({"activation": "gelu"})


def test_neural_sdf_corrupt_artifact(tmp_path):
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"\x00" * 64)
    with pytest.raises(InputError, match="bad.pt"):
        load_family("neural_sdf").load(str(bad))


# ---- gan_sdf -----------------------------------------------------------------------------------
GAN_FAST = {"batch": 64, "lr": 1e-3, "lr_d": 1e-3}


def test_gan_sdf_architecture_matches_the_thesis():
    rep = load_family("gan_sdf")({})
    # Linear(3,256) + Conv1d(1,16,7) + Conv1d(16,32,5) + Linear(7744,1)
    assert rep.n_params() == (3 * 256 + 256) + (16 * 7 + 16) + (32 * 16 * 5 + 32) + (7744 + 1)
    with pytest.raises(InputError, match="near_term"):
        load_family("gan_sdf")({"near_term": "cubic"})
    with pytest.raises(InputError, match="adversarial"):
        load_family("gan_sdf")({"adversarial": "wasserstein"})
    with pytest.raises(InputError, match="target_scale"):
        load_family("gan_sdf")({"target_scale": 0})


def test_gan_sdf_least_squares_term_reads_d_after_its_sigmoid():
    """Eq. 4.2: mean (D - 1)^2 with D in (0, 1); at logit 0 D = 1/2, at logit ln 3 D = 3/4."""
    from ddfbench.models.gan_sdf import adversarial_losses
    g_term, d_loss = adversarial_losses("least_squares")
    logits = torch.tensor([0.0, float(np.log(3.0))])
    assert float(g_term(logits)) == pytest.approx((0.25 + 0.0625) / 2)
    # D: real judged 3/4 -> (1/4)^2, fake judged 1/2 -> (1/2)^2
    assert float(d_loss(logits[1:], logits[:1])) == pytest.approx(0.0625 + 0.25)


def test_gan_sdf_answers_in_unit_cube_units_in_chunks():
    """The generator learns target_scale * sdf; sdf() divides it back, and chunked evaluation changes nothing."""
    p = near_points(3000)
    one = load_family("gan_sdf")({"target_scale": 1.0, "eval_batch": 65536})
    four = load_family("gan_sdf")({"target_scale": 4.0, "eval_batch": 7})
    four.net.load_state_dict(one.net.state_dict())
    np.testing.assert_allclose(four.sdf(p) * 4.0, one.sdf(p), rtol=1e-5, atol=1e-6)


def test_gan_sdf_epochs_cap_the_steps(sphere):
    mesh, oracle, samples = sphere
    rep = load_family("gan_sdf")({**GAN_FAST, "epochs": 0.01}, DOMAIN)
    stats = rep.fit(FitData(samples, mesh, oracle), Budget(max_steps=1000, max_seconds=600))
    assert stats.steps == 4  # 0.01 of 20,000 samples at 64 per step: 3.1 steps, rounded up


@pytest.mark.slow
def test_gan_sdf_seed_sweep_reports_its_failure_rate(sphere, tmp_path):
    """Several seeds of the thesis loss (least squares, targets x4) plus the L1 anchor on the sphere;
    failures are counted, not hidden.

    A seed fails unless, within 0.3 of the sphere, the field's sign is right at >= 90 % of the points
    farther than 0.02 from it and its mean error is below half an untrained generator's. Measured
    (200 steps, 3 seeds, 1 thread): errors 0.033-0.063, signs 99-99.8 %; with unscaled targets
    (target_scale 1) errors 0.056-0.084 and 2 of 3 seeds over the bound.
    """
    mesh, oracle, samples = sphere
    p = near_points(2000, band=0.3)
    ref = np.linalg.norm(p, axis=1) - RADIUS
    far = np.abs(ref) > 0.02
    start = np.abs(load_family("gan_sdf")({}).sdf(p) - ref).mean()
    scores, failed = [], 0
    for seed in range(3):
        rep = load_family("gan_sdf")({**GAN_FAST, "w_anchor": 1.0, "target_scale": 4.0}, DOMAIN)
        stats = rep.fit(FitData(samples, mesh, oracle), Budget(max_steps=200, max_seconds=120, seed=seed))
        s = rep.sdf(p)
        err, signs = float(np.abs(s - ref).mean()), float((np.sign(s[far]) == np.sign(ref[far])).mean())
        scores.append((round(err, 4), round(signs, 3)))
        failed += int(stats.status != "ok" or signs < 0.9 or err > 0.5 * start)
    print(f"\ngan_sdf sphere sweep: (mean error, sign agreement) per seed {scores}, failure rate {failed}/3")
    assert failed == 0, f"gan_sdf failed on {failed} of 3 seeds: {scores} (untrained error {start:.3f})"
    check_round_trip(rep, tmp_path, "gan_sdf")


def test_gan_sdf_nan_guard_fires_on_divergence(sphere):
    mesh, oracle, samples = sphere
    rep = load_family("gan_sdf")({**GAN_FAST, "lr": 1e12, "lr_d": 1e12}, DOMAIN)
    stats = rep.fit(FitData(samples, mesh, oracle), Budget(max_steps=100, max_seconds=30))
    assert stats.status == "failed" and "non-finite" in stats.message
