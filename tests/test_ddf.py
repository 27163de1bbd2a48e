"""The DDF family on a sphere: fit, rays, normals, mesh, artifacts, the paper preset and the NaN guard."""

import os

import numpy as np
import pytest
import torch
import trimesh
from omegaconf import OmegaConf

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import box_entry
from ddfbench.core.representation import Budget, FitData, RayStatus
from ddfbench.models import load_family
from ddfbench.models.ddf import DDF, fibonacci_directions, line_entry_labels, line_vote
from ddfbench.models.ddf import family as ddf_module  # ONE_PASS_HIT_SHARE lives there
from ddfbench.sampling.samples import Samples
from ddfbench.truth.oracle import Oracle

R0 = 0.4
CONF = os.path.join(os.path.dirname(__file__), "..", "conf", "model")
SMALL = {"width": 128, "depth": 3, "pos_freqs": 4, "dir_freqs": 2, "batch": 2048, "lr": 3e-3, "vis_weight": 0.1,
         "udf_directions": 16, "eval_batch": 16384}


def unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def ray_samples(oracle, n, seed):
    """Half random points in the box, half points marched off the surface looking back at it; exact t."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-0.6, 0.6, (n, 3))
    d = unit(rng.normal(size=(n, 3)))
    m = n // 2
    p = oracle.closest_point(rng.uniform(-0.6, 0.6, (m, 3)))[0]
    out = unit(rng.normal(size=(m, 3)))
    out[np.einsum("ij,ij->i", out, p) < 0] *= -1
    x[:m], d[:m] = p + rng.uniform(0, 0.3, (m, 1)) * out, -out
    t = oracle.first_hit(x, d)[0]
    return Samples(x=x.astype(np.float32), d=d.astype(np.float32), t=t, hit=np.isfinite(t))


def analytic_hit(o, d):
    """First hit of rays with the sphere |x| = R0 (inf on a miss), brute force quadratic."""
    b = np.einsum("ij,ij->i", o, d)
    disc = b * b - (np.einsum("ij,ij->i", o, o) - R0**2)
    sq = np.sqrt(np.maximum(disc, 0))
    t = np.where(-b - sq > 0, -b - sq, -b + sq)
    return np.where((disc > 0) & (t > 0), t, np.inf)


@pytest.fixture(scope="module")
def sphere_oracle():
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=R0)
    return mesh, Oracle(mesh)


@pytest.fixture(scope="module")
def fitted(sphere_oracle):
    mesh, oracle = sphere_oracle
    rep = DDF(SMALL)
    stats = rep.fit(FitData(ray_samples(oracle, 200_000, 0), mesh, oracle),
                    Budget(max_steps=700, max_seconds=120, seed=0, n_probes=0))
    return rep, stats


def camera_rays(n, seed):
    rng = np.random.default_rng(seed)
    o = unit(rng.normal(size=(n, 3))) * 1.5
    target = rng.uniform(-0.5, 0.5, (n, 3))
    return o.astype(np.float32), unit(target - o).astype(np.float32)


def test_fit_reaches_small_error_on_a_sphere(fitted):
    rep, stats = fitted
    assert stats.status == "ok" and stats.steps == 700
    o, d = camera_rays(20000, 1)
    truth = analytic_hit(o, d)
    hits = rep.intersect(o, d, normals=False)
    assert (hits.hit == np.isfinite(truth)).mean() > 0.97
    both = hits.hit & np.isfinite(truth)
    assert np.median(np.abs(hits.t[both] - truth[both])) < 0.005
    assert set(np.unique(hits.status)) <= {RayStatus.HIT, RayStatus.MISS}
    assert np.isinf(hits.t[~hits.hit]).all()


def test_distance_and_visibility_answer_rays_from_any_point(fitted):
    """phi(x, d) and the visibility output, asked at points inside the box (no box entry): the sphere's
    hit distance and mask; at box-entry points they are what intersect adds to t_entry."""
    rep, _ = fitted
    rng = np.random.default_rng(8)
    x = rng.uniform(-0.55, 0.55, (6000, 3)).astype(np.float32)
    x = x[np.linalg.norm(x, axis=1) > R0 + 0.02]
    d = unit(rng.normal(size=(len(x), 3))).astype(np.float32)
    truth, vis, dist = analytic_hit(x, d), rep.visibility(x, d), rep.distance(x, d)
    assert vis.dtype == bool and dist.dtype == np.float32 and (dist >= 0).all()
    assert (vis == np.isfinite(truth)).mean() > 0.95
    both = vis & np.isfinite(truth)
    assert np.median(np.abs(dist[both] - truth[both])) < 0.01
    o, dc = camera_rays(3000, 9)
    t_entry = box_entry(o, dc, 0.6)[0]
    hits = rep.intersect(o, dc, normals=False)
    at_entry = (o + t_entry[:, None] * dc).astype(np.float32)
    np.testing.assert_allclose(hits.t[hits.hit], (t_entry + rep.distance(at_entry, dc))[hits.hit], rtol=1e-6)
    assert rep.visibility(at_entry, dc)[hits.hit].all()


def analytic_line_distance(x, d):
    """Signed distance from x along d to the first crossing of the sphere by the line, seen from its box entry."""
    back = box_entry(x, -d, 0.6)[1]
    return analytic_hit(x - back[:, None] * d, d) - back


def test_line_distance_matches_the_sphere_from_the_box_entry(fitted):
    rep, _ = fitted
    rng = np.random.default_rng(5)
    x = rng.uniform(-0.5, 0.5, (4000, 3)).astype(np.float32)
    d = unit(rng.normal(size=(4000, 3))).astype(np.float32)
    s, truth = rep.line_distance(x, d), analytic_line_distance(x, d)
    assert (np.isfinite(s) == np.isfinite(truth)).mean() > 0.95
    clear = np.isfinite(s) & np.isfinite(truth) & (np.abs(truth) > 0.05)
    assert (np.sign(s[clear]) == np.sign(truth[clear])).mean() > 0.97
    both = np.isfinite(s) & np.isfinite(truth)
    assert np.median(np.abs(s[both] - truth[both])) < 0.01


def slab_lines(h, dirs, thickness=0.3):
    """Line distances at height h above the top face z=0 of a solid slab -thickness < z < 0 (analytic)."""
    dz = dirs[:, 2]
    with np.errstate(divide="ignore"):
        down = np.where(dz < -1e-3, h / -dz, np.inf)  # entering from above: the top face, h / |dz| ahead
        up = np.where(dz > 1e-3, -(h + thickness) / dz, np.inf)  # entering from below: the bottom face, behind
    return np.where(dz < 0, down, up)[None, :]


def test_line_vote_takes_the_sign_of_the_side_and_outvotes_wrong_lines():
    dirs = fibonacci_directions(32)
    band = 0.02
    heights = np.array([-0.1, -0.03, -0.005, 0.005, 0.03, 0.1])
    values = np.array([line_vote(slab_lines(h, dirs), 12, band, 3)[0][0] for h in heights])
    assert np.array_equal(np.sign(values), np.sign(heights))
    assert np.all(np.diff(values) > 0)  # grows with the height through the surface
    for h in (-0.1, -0.03, 0.03, 0.1):  # two lines claim a surface right at the point
        s = slab_lines(h, dirs)
        s[0, np.argsort(np.abs(s[0]))[-2:]] = 1e-3 * np.sign(-h)
        assert np.sign(line_vote(s, 12, band, 3)[0][0]) == np.sign(h)
    far = np.full((1, 32), np.inf)  # every line misses: far outside
    assert line_vote(far, 12, band, 3)[0][0] > band


def test_line_entry_labels_are_exact_on_the_sphere():
    rng = np.random.default_rng(7)
    n = 3000
    x = rng.uniform(-0.6, 0.6, (n, 3)).astype(np.float32)
    d = unit(rng.normal(size=(n, 3))).astype(np.float32)
    line_hit = np.isfinite(analytic_hit(x, d)) | np.isfinite(analytic_hit(x, -d))
    rows = rng.choice(n, 2000, replace=False)
    xe, de, he = line_entry_labels(x, d, line_hit, 0.6, rows)
    assert np.allclose(np.abs(xe).max(1), 0.6, atol=1e-5)  # on the box boundary
    assert np.array_equal(he, np.isfinite(analytic_hit(xe, de))) and np.array_equal(he, line_hit[rows])
    assert 100 < he.sum() < len(he) - 100


def test_signed_mesh_lies_on_the_sphere(fitted):
    rep, _ = fitted
    mesh = rep.to_mesh(40)
    assert len(mesh.faces) > 100 and rep.extract_info["field_evals"] < 0.5 * 40**3
    r = np.linalg.norm(mesh.vertices, axis=1)
    assert np.median(np.abs(r - R0)) < 0.005
    assert np.percentile(np.abs(r - R0), 90) < 0.02


def test_paper_udf_mesh_lies_on_the_sphere(fitted):
    rep, _ = fitted
    udf = DDF({**rep.cfg, "mesh_field": "udf"})
    udf.net.load_state_dict(rep.net.state_dict())
    mesh = udf.to_mesh(40)
    assert len(mesh.faces) > 100
    r = np.linalg.norm(mesh.vertices, axis=1)
    assert np.median(np.abs(r - R0)) < 0.01
    assert np.percentile(np.abs(r - R0), 95) < 0.03


def test_normals_are_unit_finite_and_match_the_mesh(fitted, sphere_oracle):
    rep, _ = fitted
    _, oracle = sphere_oracle
    o, d = camera_rays(5000, 2)
    hits = rep.intersect(o, d, normals=True)
    n = hits.normal[hits.hit]
    assert np.isfinite(n).all() and np.allclose(np.linalg.norm(n, axis=1), 1, atol=1e-5)
    assert (np.einsum("ij,ij->i", n, d[hits.hit]) < 0).all()
    _, tri, gt_normal = oracle.first_hit(o, d)
    both = hits.hit & (tri >= 0)
    cos = np.einsum("ij,ij->i", hits.normal[both], gt_normal[both])
    assert np.median(np.degrees(np.arccos(np.clip(cos, -1, 1)))) < 8
    assert rep.intersect(o, d, normals=False).stats == {"field_evals": 5000, "backward_passes": 0}


def test_one_pass_and_two_pass_normals_agree_and_count_their_work(fitted, monkeypatch):
    """A chunk with many hits is differentiated whole (one pass); one with few hits re-runs its hits."""
    rep, _ = fitted
    o, d = camera_rays(5000, 2)
    monkeypatch.setattr(ddf_module, "ONE_PASS_HIT_SHARE", 0.0)
    one = rep.intersect(o, d, normals=True)
    monkeypatch.setattr(ddf_module, "ONE_PASS_HIT_SHARE", 1.01)
    two = rep.intersect(o, d, normals=True)
    k = int(one.hit.sum())
    assert 0 < k < 5000 and np.array_equal(one.hit, two.hit) and np.array_equal(one.t, two.t)
    assert np.allclose(one.normal, two.normal, atol=1e-5) and np.array_equal(one.normal_valid, two.normal_valid)
    assert one.stats == {"field_evals": 5000, "backward_passes": 5000}
    assert two.stats == {"field_evals": 5000 + k, "backward_passes": k}


def test_normals_where_the_gradient_vanishes_are_flagged():
    rep = DDF({**SMALL, "width": 8, "depth": 1, "param": "point"})  # "ray" adds -x.d: never flat
    for p in rep.net.parameters():
        torch.nn.init.zeros_(p)  # constant field: zero gradient everywhere
    d = unit(np.random.default_rng(0).normal(size=(10, 3))).astype(np.float32)
    n, valid = rep.normals(np.zeros((10, 3), np.float32), d)
    assert not valid.any() and np.allclose(n, -d)


def test_udf_takes_the_min_over_visible_directions(fitted):
    rep, _ = fitted
    dirs = fibonacci_directions(64)
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1, atol=1e-6) and np.abs(dirs.mean(0)).max() < 0.02
    x = np.array([[0.0, 0.0, 0.5], [0.0, 0.3, 0.0], [0.25, 0.25, 0.25]], np.float32)
    udf = rep.udf(x, dirs)
    exact = np.abs(np.linalg.norm(x, axis=1) - R0)
    assert np.allclose(udf, exact, atol=0.02)
    far = rep.udf(np.array([[0.0, 0.0, 0.59]], np.float32), np.array([[0.0, 0.0, 1.0]], np.float32))
    assert np.isinf(far).all()  # looking away from the sphere: no visible direction


def test_rays_missing_the_box_are_misses_without_evaluations(fitted):
    rep, _ = fitted
    o = np.array([[2.0, 2.0, 2.0], [0.0, 0.0, 1.5]], np.float32)
    d = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0]], np.float32)
    hits = rep.intersect(o, d)
    assert list(hits.hit) == [False, True] and hits.stats["field_evals"] == 1
    assert abs(hits.t[1] - (1.5 - R0)) < 0.01


def test_save_load_round_trip_and_storage(fitted, tmp_path):
    rep, _ = fitted
    o, d = camera_rays(3000, 3)
    saved = rep.save(str(tmp_path / "model"))
    assert os.listdir(tmp_path) == ["model.pt"]  # one file, published by rename (no temporary left)
    assert rep.storage_bytes() == os.path.getsize(saved)
    back = load_family("ddf").load(saved)
    a, b = rep.intersect(o, d), back.intersect(o, d)
    assert np.array_equal(a.t, b.t) and np.array_equal(a.normal, b.normal)
    assert back.n_params() == rep.n_params()

    half = DDF({**rep.cfg, "storage_dtype": "float16"})
    half.net.load_state_dict(rep.net.state_dict())
    half_path = half.save(str(tmp_path / "half"))
    assert half.storage_bytes() < 0.6 * rep.storage_bytes()
    c = DDF.load(half_path).intersect(o, d, normals=False)
    live = half.intersect(o, d, normals=False)  # the saved model answers as its float16 artifact, not in float32
    assert np.array_equal(live.t, c.t) and np.array_equal(live.hit, c.hit) and not np.array_equal(live.t, a.t)
    both = c.hit & a.hit
    assert (c.hit == a.hit).mean() > 0.99 and np.abs(c.t[both] - a.t[both]).max() < 0.01


def test_load_rejects_foreign_and_broken_artifacts(tmp_path):
    with pytest.raises(InputError, match=r"^ddf artifact \S*/missing: unreadable \("):
        DDF.load(str(tmp_path / "missing"))
    torch.save({}, tmp_path / "empty.pt")
    with pytest.raises(InputError, match="unreadable"):
        DDF.load(str(tmp_path / "empty.pt"))
    torch.save({"header": '{"family": "mesh", "cfg": {}}', "state_dict": {}}, tmp_path / "foreign.pt")
    with pytest.raises(InputError, match="holds family 'mesh'"):
        DDF.load(str(tmp_path / "foreign.pt"))


def test_paper_preset_builds_and_trains_a_few_steps(sphere_oracle):
    mesh, oracle = sphere_oracle
    cfg = OmegaConf.to_container(OmegaConf.load(os.path.join(CONF, "ddf_paper.yaml")))
    rep = DDF({**cfg, "batch": 256})
    wn = [m for m in rep.net.modules() if isinstance(m, torch.nn.Linear) and hasattr(m, "parametrizations")]
    drop = [m for m in rep.net.modules() if isinstance(m, torch.nn.Dropout)]
    assert len(wn) == 8 and len(drop) == 8 and all(m.out_features == 512 for m in wn)
    stats = rep.fit(FitData(ray_samples(oracle, 5000, 1), mesh, oracle), Budget(max_steps=3, max_seconds=60))
    assert stats.status == "ok" and stats.steps == 3
    hits = rep.intersect(*camera_rays(100, 4))
    assert np.isfinite(hits.normal).all()


def test_default_preset_matches_the_code_defaults():
    cfg = OmegaConf.to_container(OmegaConf.load(os.path.join(CONF, "ddf.yaml")))
    assert DDF(cfg).cfg == DDF({}).cfg


def test_nan_guard_fires_on_forced_divergence(sphere_oracle):
    mesh, oracle = sphere_oracle
    rep = DDF({**SMALL, "lr": 1e30, "grad_clip": 0, "lr_schedule": "constant"})
    stats = rep.fit(FitData(ray_samples(oracle, 5000, 2), mesh, oracle), Budget(max_steps=500, max_seconds=60))
    assert stats.status == "failed" and "non-finite" in stats.message and stats.steps < 500


def test_bad_config_and_samples_raise_input_errors(sphere_oracle):
    mesh, oracle = sphere_oracle
    with pytest.raises(InputError, match=r"^model\.param 'polar': unknown \(one of point, ray\)$"):
        DDF({"param": "polar"})
    with pytest.raises(InputError, match=r"^model\.width 0: must be a positive integer$"):
        DDF({"width": 0})
    with pytest.raises(InputError, match=r"^model\.mesh_band 0: must be > 0$"):
        DDF({"mesh_band": 0})
    with pytest.raises(InputError, match=r"^model\.entry_share 1\.0: must be in \[0, 1\)$"):
        DDF({"entry_share": 1.0})
    with pytest.raises(InputError, match=r"^model\.mesh_field 'points': unknown \(one of signed, udf\)$"):
        DDF({"mesh_field": "points"})
    with pytest.raises(InputError, match=r"^model\.visibility 'clamp' needs model\.loss 'clamp' or 'clamp_misses'"):
        DDF({"visibility": "clamp", "loss": "l1"})
    for delta in (0.0, float("inf")):
        with pytest.raises(InputError, match="model.delta"):
            DDF({"visibility": "clamp", "loss": "clamp_misses", "delta": delta})
    assert DDF({"visibility": "clamp", "loss": "clamp_misses", "delta": 0.5}).cfg["loss"] == "clamp_misses"
    with pytest.raises(InputError, match=r"^model ddf: needs ray samples \(x, d, t, hit\); the sampler gave none$"):
        DDF(SMALL).fit(FitData(Samples(x=np.zeros((4, 3), np.float32)), mesh, oracle), Budget(max_steps=1))


def test_paper_lr_preset_is_the_paper_preset_but_for_its_named_deviations():
    """conf/model/ddf_paper_lr.yaml changes only what its comment names (lr, batch, loss, dropout, position
    encoding); ddf_paper stays as written.
    (Its fit_steps budget and the experiments it joins are about the runs, not the model.)"""
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=os.path.abspath(CONF), version_base="1.3"):
        paper = OmegaConf.to_container(compose(config_name="ddf_paper"))
        trainable = OmegaConf.to_container(compose(config_name="ddf_paper_lr"))
    assert paper["lr"] == 1e-7 and trainable["lr"] == 1e-3
    about_runs = {"fit_steps", "experiments"}
    assert {k for k in paper if paper[k] != trainable.get(k)} - about_runs == {"lr", "batch", "loss", "dropout", "pos_freqs"}
    assert trainable.keys() == paper.keys()


@pytest.mark.parametrize("mode", ["clamp", "clamp_misses"])
def test_clamp_loss_only_the_printed_clamp_drops_a_near_hit_predicted_beyond_delta(mode):
    """Eq. 8 as printed gives no gradient to any prediction beyond delta (where ddf_paper_lr's fits sat at
    the all-miss loss); clamp_misses still pulls a near hit back. Both leave a miss beyond delta alone and
    agree wherever the prediction is below delta."""
    from ddfbench.models.ddf.fit import clamp_loss

    # near hit beyond delta, miss beyond delta, far hit (t >= delta) beyond delta, near hit, miss below delta
    pred = torch.tensor([2.0, 2.0, 2.0, 0.3, 0.5], requires_grad=True)
    t = torch.tensor([0.1, 0.0, 1.5, 0.2, 0.0])
    hit = torch.tensor([True, False, True, True, False])
    loss = clamp_loss(pred, t, hit, 1.0, mode)
    assert torch.allclose(loss, torch.tensor([1.9 if mode == "clamp_misses" else 0.9, 0.0, 0.0, 0.1, 0.5]))
    loss.sum().backward()
    assert pred.grad[1] == pred.grad[2] == 0 and (pred.grad[0] > 0) == (mode == "clamp_misses")
    assert torch.equal(pred.grad[3:], torch.tensor([1.0, -1.0]))


def test_the_clamp_loss_clamps_from_above_only_as_docs_papers_md_says():
    """Eq. 8's clamp floors at -delta too; ours does not (docs/papers.md names it): a prediction below -delta keeps
    its gradient, one above delta has none in mode clamp."""
    from ddfbench.models.ddf.fit import clamp_loss

    pred = torch.tensor([-2.0, 2.0], requires_grad=True)
    clamp_loss(pred, torch.tensor([0.5, 0.5]), torch.tensor([True, True]), 1.0, "clamp").sum().backward()
    assert pred.grad.tolist() == [-1.0, 0.0]
