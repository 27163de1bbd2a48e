"""Renderer: pass planning, exact ray counts per preset, shading against closed forms, accuracy, artifacts."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
import trimesh
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from PIL import Image

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import BOX_HALF
from ddfbench.core.representation import Hits, RayStatus, Representation
from ddfbench.render import mesh_reference, render_scene
from ddfbench.render.camera import Camera, orbit_cameras
from ddfbench.render.compare import PSNR_CAP, image_metrics
from ddfbench.render.counting import CountedTracer, clean_hits
from ddfbench.render.images import write_png
from ddfbench.render.integrator import Frames, primary_rays, render
from ddfbench.render.scene import parse_scene, plan_passes
from ddfbench.render.timing import time_renders

SCENE_DIR = os.path.join(os.path.dirname(__file__), "..", "conf", "scene")
PRESETS = ("depth", "normals", "shaded", "path", "paper_fig4")


def preset(name: str, **overrides) -> dict:
    """The composed preset YAML (Hydra, as the runner sees it) with top-level keys replaced."""
    with initialize_config_dir(config_dir=os.path.abspath(SCENE_DIR), version_base="1.3"):
        cfg = OmegaConf.to_container(compose(config_name=name))
    cfg.update(overrides)
    return cfg


class AnalyticSphere(Representation):
    """Exact ray–sphere intersection. Reports 1 field eval per ray, 1 backward pass per ray asked for
    normals and 3 trace steps per ray, so the counting layer's tallies can be checked exactly."""

    family = "analytic_sphere"
    configure = classmethod(lambda cls, cfg: dict(cfg))  # a test double: no conf/model YAML to check cfg against

    def __init__(self, radius: float = 0.4, center=(0.0, 0.0, 0.0)):
        super().__init__({})
        self.radius, self.center = radius, np.asarray(center, np.float64)

    def intersect(self, origins, directions, normals=True):
        o, d = origins.astype(np.float64) - self.center, directions.astype(np.float64)
        b = np.einsum("ij,ij->i", o, d)
        disc = b * b - (np.einsum("ij,ij->i", o, o) - self.radius**2)
        root = np.sqrt(np.maximum(disc, 0))
        near, far = -b - root, -b + root
        t = np.where(near > 0, near, np.where(far > 0, far, np.inf))
        t = np.where(disc > 0, t, np.inf)
        hit = np.isfinite(t)
        n = np.zeros_like(o)
        n[hit] = (o[hit] + t[hit, None] * d[hit]) / self.radius
        n[hit] *= -np.sign(np.einsum("ij,ij->i", n[hit], d[hit]))[:, None]
        k = len(t)
        return Hits(t=t.astype(np.float32), hit=hit, normal=n.astype(np.float32) if normals else np.zeros((k, 3), np.float32),
                    status=np.where(hit, RayStatus.HIT, RayStatus.MISS).astype(np.int8), normal_valid=hit & normals,
                    stats={"field_evals": k, "backward_passes": k if normals else 0, "trace_steps": 3 * k})

    def fit(self, data, budget, probe=None):
        raise NotImplementedError

    def to_mesh(self, resolution):
        raise NotImplementedError

    def save(self, path):
        raise NotImplementedError

    @classmethod
    def load(cls, path, domain=0.6):
        raise NotImplementedError


class Garbage(AnalyticSphere):
    """The sphere's answer spoiled the ways a learned field can spoil it: NaN and inf t on 'hits',
    NaN and zero normals, undecided rays."""

    family = "garbage"

    def intersect(self, origins, directions, normals=True):
        h = super().intersect(origins, directions, normals)
        idx = np.arange(len(h.t))
        h.t[idx % 5 == 1] = np.nan
        h.t[idx % 5 == 2] = np.inf
        h.hit[idx % 5 != 0] = True
        h.normal[idx % 3 == 0] = np.nan
        h.normal[idx % 3 == 1] = 0.0
        h.status[idx % 7 == 0] = RayStatus.UNDECIDED
        return h


def mesh_rep(mesh: trimesh.Trimesh):
    return mesh_reference(mesh, BOX_HALF)


def lambert(points, normals, light, albedo):
    """Independent closed form of one light's reflected radiance ρ/π·E·max(0, cos) at points (M,3)."""
    if light["type"] == "directional":
        wi = -np.asarray(light["direction"], float) / np.linalg.norm(light["direction"])
        wi = np.broadcast_to(wi, points.shape)
        e = np.full(len(points), light["intensity"])
    else:
        delta = np.asarray(light["position"]) - points
        r = np.linalg.norm(delta, axis=1)
        wi, e = delta / r[:, None], light["intensity"] / r**2
    cos = np.einsum("ij,ij->i", normals, wi)
    return albedo / math.pi * e * np.maximum(cos, 0), cos > 0


# ---- scene → passes ------------------------------------------------------------------------------
def test_presets_trigger_the_passes_the_rules_give():
    expected = {  # (normals, shaded, path, shadow rays, bounce rays), from the rules
        "depth": (False, False, False, False, False),
        "normals": (True, False, False, False, False),
        "shaded": (True, True, False, True, False),
        "path": (True, False, True, True, True),
        "paper_fig4": (True, True, True, True, True),
    }
    for name, flags in expected.items():
        p = plan_passes(parse_scene(preset(name)))
        assert (p.normals, p.shaded, p.path, p.shadow_rays, p.bounce_rays) == flags, name


def test_shadow_and_bounce_rays_need_every_condition():
    assert not plan_passes(parse_scene(preset("shaded", lights=[]))).shadow_rays
    assert not plan_passes(parse_scene(preset("shaded", outputs=["depth", "shaded"]))).shadow_rays
    assert not plan_passes(parse_scene(preset("path", max_depth=1))).bounce_rays
    assert plan_passes(parse_scene(preset("depth", outputs=["mask", "shaded"]))).normals


@pytest.mark.parametrize("bad, message", [
    ({"outputs": ["depth", "albedo"]}, "unknown"),
    ({"outputs": []}, "empty"),
    ({"outputs": ["depth", "shadow"]}, "'shadow' needs"),
    ({"spp": 0}, "scene.spp"),
    ({"width": 2.5}, "scene.width"),
    ({"albedo": 1.5}, "albedo"),
    ({"lights": [{"type": "spot", "position": [0, 1, 0]}]}, "type"),
    ({"lights": [{"type": "point"}]}, "position"),
    ({"cameras": {"fov_deg": 190}}, "fov_deg"),
    ({"ray_offset": -1}, "ray_offset"),
])
def test_bad_scene_values_are_input_errors(bad, message):
    with pytest.raises(InputError, match=message):
        parse_scene(preset("shaded", **bad))


# ---- cameras -------------------------------------------------------------------------------------
def test_orbit_cameras_sit_on_their_circle():
    cams = orbit_cameras(4, 2.5, 30.0, 10.0, 40.0, 8, 6, np.array([0.1, 0.0, 0.0]))
    for cam in cams:
        offset = cam.position - cam.look_at
        assert np.linalg.norm(offset) == pytest.approx(2.5)
        assert math.degrees(math.asin(offset[1] / 2.5)) == pytest.approx(30.0)
    azimuths = [math.degrees(math.atan2(c.position[0] - 0.1, c.position[2])) for c in cams]
    assert np.allclose(np.diff(azimuths) % 360, 90.0)


def test_camera_rays_follow_the_pinhole_model():
    w, h, fov = 7, 5, 50.0
    cam = Camera(np.array([0.3, 0.2, 2.0]), np.array([0.0, 0.1, 0.0]), fov, w, h)
    o, d = cam.rays()
    forward = (cam.look_at - cam.position) / np.linalg.norm(cam.look_at - cam.position)
    assert o.shape == d.shape == (w * h, 3) and np.allclose(o, cam.position)
    assert np.allclose(np.linalg.norm(d, axis=1), 1, atol=1e-6)
    assert np.allclose(d[(h // 2) * w + w // 2], forward, atol=1e-6)  # odd size: the centre pixel
    tan_h = math.tan(math.radians(fov / 2))
    corner = math.atan(math.hypot(tan_h * w / h * (1 - 1 / w), tan_h * (1 - 1 / h)))
    assert math.acos(float(d[0] @ forward)) == pytest.approx(corner, abs=1e-5)
    assert d[0] @ np.array([0.0, 1.0, 0.0]) > d[-1] @ np.array([0.0, 1.0, 0.0])  # row 0 is the top


def test_sphere_silhouette_has_the_width_its_angle_gives():
    r, dist, fov, w = 0.4, 2.0, 40.0, 101
    scene = parse_scene(preset("depth", width=w, height=w, cameras={"n": 1, "radius": dist, "elevation_deg": 0.0,
                                                                   "fov_deg": fov}))
    frames, _ = render(AnalyticSphere(r), scene, plan_passes(scene), seed=0)
    width_px = frames.mask[0, w // 2].sum()
    expected = w * math.tan(math.asin(r / dist)) / math.tan(math.radians(fov / 2))
    assert abs(width_px - expected) <= 2


# ---- counting layer ------------------------------------------------------------------------------
def test_clean_hits_turns_bad_answers_into_misses_and_safe_normals():
    d = np.tile(np.array([[0.0, 0.0, -1.0]], np.float32), (4, 1))
    raw = Hits(t=np.array([1.0, np.nan, -0.5, 2.0], np.float32), hit=np.array([True, True, True, True]),
               normal=np.array([[0, 0, 2.0], [0, 0, 1], [0, 0, 1], [0, 0, 0]], np.float32),
               status=np.full(4, RayStatus.HIT, np.int8))
    h = clean_hits(raw, d, "x")
    assert h.hit.tolist() == [True, False, False, True]
    assert np.isinf(h.t[1:3]).all() and h.t[0] == 1.0
    assert np.allclose(h.normal[0], [0, 0, 1])  # unit length
    assert np.allclose(h.normal[3], [0, 0, 1]) and not h.normal_valid[3]  # zero normal → −d
    raw.normal[0] = [0, 0, -1]  # facing away from the ray: flipped
    assert np.allclose(clean_hits(raw, d, "x").normal[0], [0, 0, 1])


def test_chunked_queries_equal_one_query_and_tally_every_call():
    rng = np.random.default_rng(0)
    o = rng.normal(size=(20, 3)) * 2
    d = -o / np.linalg.norm(o, axis=1, keepdims=True)
    whole, chunked = CountedTracer(AnalyticSphere(), chunk=100), CountedTracer(AnalyticSphere(), chunk=7)
    a, b = whole.cast("bounce", o, d, normals=True), chunked.cast("bounce", o, d, normals=True)
    assert np.array_equal(a.t, b.t) and np.array_equal(a.normal, b.normal)
    assert chunked.counts["intersect_calls"] == 3 and whole.counts["intersect_calls"] == 1
    assert chunked.counts["bounce_rays"] == 20 and chunked.counts["field_evals"] == 20
    assert chunked.counts["backward_passes"] == 20 and chunked.counts["trace_steps"] == 60


# ---- exact counts per preset ---------------------------------------------------------------------
@pytest.mark.parametrize("name", PRESETS)
def test_each_preset_casts_exactly_the_rays_its_passes_need(name):
    """Convex sphere: shadow rays go toward every light in front of a primary hit and never hit; every
    bounce ray escapes, so vertices after the first do no work."""
    w, h = 12, 10
    cfg = preset(name, width=w, height=h)
    scene = parse_scene(cfg)
    sphere = AnalyticSphere(0.4)
    frames, counts = render(sphere, scene, plan_passes(scene), seed=3)
    n = len(scene.cameras) * w * h * scene.spp
    o, d = primary_rays(scene, 3)
    ref = sphere.intersect(o, d)
    points = o[ref.hit] + ref.t[ref.hit, None] * d[ref.hit]
    shading = bool({"shaded", "path"} & set(cfg["outputs"]))
    shadows = sum(int(lambert(points, ref.normal[ref.hit], light, 0.8)[1].sum()) for light in cfg["lights"]) \
        if shading and "shadow" in cfg["outputs"] else 0
    bounces = int(ref.hit.sum()) if "path" in cfg["outputs"] and cfg["max_depth"] > 1 else 0
    normals = shading or "normal" in cfg["outputs"]
    assert counts["primary_rays"] == n
    assert counts["shadow_rays"] == shadows
    assert counts["bounce_rays"] == bounces
    assert counts["field_evals"] == n + shadows + bounces
    assert counts["backward_passes"] == (n if normals else 0) + bounces
    assert counts["trace_steps"] == 3 * (n + shadows + bounces)
    if name == "depth":
        assert counts["shadow_rays"] == counts["bounce_rays"] == counts["backward_passes"] == 0
    if name in ("shaded", "path", "paper_fig4"):
        assert shadows > 0
    if name in ("path", "paper_fig4"):
        assert bounces > 0


def test_path_inside_a_sphere_matches_the_closed_form_and_counts():
    """Camera inside a sphere of radius R, point light of intensity I at its centre: every vertex sees
    the light at normal incidence (E = I/R²) and every bounce hits the wall again, so with
    cosine-weighted bounces each pixel is exactly ρ/π·I/R²·Σ_{k<max_depth} ρ^k."""
    radius, intensity, rho, depth, spp = 3.0, 2.0, 0.6, 4, 2
    cfg = preset("path", width=6, height=5, spp=spp, max_depth=depth, albedo=rho, environment=0.5,
                 lights=[{"type": "point", "position": [0.0, 0.0, 0.0], "intensity": intensity}])
    scene = parse_scene(cfg)
    frames, counts = render(AnalyticSphere(radius), scene, plan_passes(scene), seed=1)
    direct = rho / math.pi * intensity / radius**2
    assert np.allclose(frames.images["path"], direct * sum(rho**k for k in range(depth)), rtol=1e-4)
    n = len(scene.cameras) * 6 * 5 * spp
    assert counts["primary_rays"] == n
    assert counts["bounce_rays"] == n * (depth - 1)
    assert counts["shadow_rays"] == n * depth
    assert np.all(frames.shadow == 0)


def test_shaded_sphere_follows_lambert_with_both_light_kinds():
    lights = [{"type": "directional", "direction": [-0.3, -1.0, -0.2], "intensity": 2.0},
              {"type": "point", "position": [1.0, 0.5, 1.5], "intensity": 0.7}]
    cfg = preset("shaded", width=16, height=16, lights=lights, albedo=0.7, background=0.25)
    scene = parse_scene(cfg)
    sphere = AnalyticSphere(0.4, center=(0.05, 0.0, 0.0))
    frames, _ = render(sphere, scene, plan_passes(scene), seed=0)
    o, d = primary_rays(scene, 0)
    ref = sphere.intersect(o, d)
    points = o + np.where(ref.hit, ref.t, 0)[:, None] * d
    expected = sum(lambert(points, ref.normal, light, 0.7)[0] for light in lights)
    expected = np.where(ref.hit, expected, 0.25).reshape(frames.mask.shape)
    assert np.allclose(frames.images["shaded"][..., 0], expected, atol=1e-4)
    assert np.all(frames.shadow == 0)  # a convex shape casts no shadow on itself: no self-hits


def test_floor_under_a_ball_is_shadowed_exactly_where_the_ball_blocks_the_light():
    floor = trimesh.creation.box(extents=(1.0, 0.02, 1.0))
    floor.apply_translation([0, -0.41, 0])
    ball = trimesh.creation.icosphere(4, 0.15)
    ball.apply_translation([0, -0.1, 0])
    rep = mesh_rep(trimesh.util.concatenate([floor, ball]))
    cfg = preset("shaded", width=48, height=48, albedo=0.5,
                 lights=[{"type": "directional", "direction": [0.0, -1.0, 0.0], "intensity": 2.0}],
                 cameras={"n": 1, "radius": 2.0, "elevation_deg": 60.0, "fov_deg": 35.0})
    scene = parse_scene(cfg)
    frames, _ = render(rep, scene, plan_passes(scene), seed=0)
    o, d = primary_rays(scene, 0)
    p = o + np.where(np.isfinite(frames.depth.ravel()), frames.depth.ravel(), 0)[:, None] * d
    on_floor = frames.mask.ravel() & (np.abs(p[:, 1] + 0.40) < 2e-3)
    radial = np.hypot(p[:, 0], p[:, 2])
    under, open_floor = on_floor & (radial < 0.12), on_floor & (radial > 0.18)
    assert under.sum() > 10 and open_floor.sum() > 100
    image, shadow = frames.images["shaded"][0, ..., 0].ravel(), frames.shadow[0].ravel()
    assert np.all(image[under] == 0) and np.all(shadow[under] == 1)
    assert np.allclose(image[open_floor], 0.5 / math.pi * 2.0, rtol=1e-4) and np.all(shadow[open_floor] == 0)


# ---- invariants across presets -------------------------------------------------------------------
def test_depth_image_is_the_same_whatever_else_is_requested():
    rep = mesh_rep(trimesh.creation.icosphere(3, 0.4))
    base, _ = render(rep, parse_scene(preset("depth", width=20, height=16)),
                     plan_passes(parse_scene(preset("depth", width=20, height=16))), seed=5)
    for name in ("normals", "path", "paper_fig4"):
        scene = parse_scene(preset(name, width=20, height=16))
        frames, _ = render(rep, scene, plan_passes(scene), seed=5)
        assert np.array_equal(frames.depth, base.depth) and np.array_equal(frames.mask, base.mask), name


@pytest.mark.parametrize("rep_kind", ["garbage", "mesh"])
def test_no_image_holds_nan_for_any_preset(rep_kind):
    rep = Garbage(0.4) if rep_kind == "garbage" else mesh_rep(trimesh.creation.icosphere(2, 0.4))
    for name in PRESETS:
        scene = parse_scene(preset(name, width=10, height=8))
        frames, counts = render(rep, scene, plan_passes(scene), seed=0)
        assert not np.isnan(frames.depth).any() and np.isfinite(frames.depth[frames.mask]).all()
        assert np.isinf(frames.depth[~frames.mask]).all()
        assert np.isfinite(frames.normal).all()
        for image in list(frames.images.values()) + ([frames.shadow] if frames.shadow is not None else []):
            assert np.isfinite(image).all(), name
        if rep_kind == "garbage":
            assert counts["undecided_rays"] > 0


# ---- accuracy and artifacts ----------------------------------------------------------------------
def test_image_metrics_on_hand_made_frames():
    mask_a = np.zeros((1, 2, 3), bool)
    mask_a[0, 0] = True  # 3 pixels
    mask_b = mask_a.copy()
    mask_b[0, 1, 0] = True  # 4 pixels, 3 shared
    depth_a = np.where(mask_a, 1.0, np.inf).astype(np.float32)
    depth_b = np.where(mask_b, 1.25, np.inf).astype(np.float32)
    up, side = np.zeros((1, 2, 3, 3), np.float32), np.zeros((1, 2, 3, 3), np.float32)
    up[..., 1], side[..., 0] = 1, 1
    img_a, img_b = np.zeros((1, 2, 3, 3), np.float32), np.full((1, 2, 3, 3), 0.1, np.float32)
    a = Frames(depth_a, mask_a, up, {"shaded": img_a})
    b = Frames(depth_b, mask_b, side, {"shaded": img_b})
    m = image_metrics(a, b, frozenset({"depth", "mask", "normal", "shaded"}))
    assert m["mask_iou"] == pytest.approx(3 / 4)
    assert m["depth_mae"] == pytest.approx(0.25)
    assert m["normal_angle_deg"] == pytest.approx(90.0)
    assert m["psnr_shaded"] == pytest.approx(20.0)
    assert image_metrics(a, a, frozenset({"shaded"}))["psnr_shaded"] == PSNR_CAP
    empty = Frames(np.full_like(depth_a, np.inf), np.zeros_like(mask_a), up)
    m = image_metrics(a, empty, frozenset({"depth", "mask"}))
    assert m["depth_mae"] is None and m["depth_pixels_compared"] == 0 and m["mask_iou"] == 0.0


def test_png_writer_round_trips_through_pil(tmp_path):
    rgb = np.random.default_rng(0).integers(0, 256, (5, 7, 3), dtype=np.uint8)
    write_png(str(tmp_path / "x.png"), rgb)
    assert np.array_equal(np.asarray(Image.open(tmp_path / "x.png").convert("RGB")), rgb)


def test_render_scene_writes_arrays_pngs_and_a_record_part(tmp_path):
    sphere = trimesh.creation.icosphere(3, 0.4)
    cfg = preset("paper_fig4", width=16, height=12, timing={"repeats": 2, "warmup": 0})
    result = render_scene(mesh_rep(sphere), mesh_rep(sphere), cfg, str(tmp_path), seed=0)
    m = result["metrics"]
    assert m["mask_iou"] == 1.0 and m["depth_mae"] == 0.0 and m["normal_angle_deg"] == 0.0
    assert m["psnr_shaded"] == m["psnr_path"] == PSNR_CAP
    assert result["artifacts"] == "renders"
    assert result["counts"]["primary_rays"] == 2 * 16 * 12 * 2
    assert result["cost"]["render_repeats"] == 2 and result["cost"]["render_cold_s"] > 0
    folder = tmp_path / "renders"
    for c in range(2):
        for out in ("depth", "mask", "normal", "shaded", "path", "shadow"):
            png = np.asarray(Image.open(folder / f"cam{c}_{out}.png"))
            assert png.shape == (12, 3 * 16 + 4, 3)
            assert np.load(folder / f"cam{c}_{out}.npy").shape[:2] == (12, 16)
            assert (folder / f"cam{c}_{out}_reference.npy").exists()


def test_depth_scene_reports_only_the_metrics_its_outputs_allow(tmp_path):
    coarse, fine = trimesh.creation.icosphere(1, 0.4), trimesh.creation.icosphere(4, 0.4)
    cfg = preset("depth", width=24, height=24, timing={"repeats": 1, "warmup": 0})
    result = render_scene(mesh_rep(coarse), mesh_rep(fine), cfg, str(tmp_path / "renders"), seed=0)
    assert set(result["metrics"]) == {"depth_mae", "mask_iou", "depth_pixels_compared"}
    # an 80-face sphere lies inside the true one: hits are later, by at most R(1 − cos of its edge's half angle)
    assert 0 < result["metrics"]["depth_mae"] < 0.4 * (1 - math.cos(math.radians(32)))
    assert result["counts"]["backward_passes"] == 0 and result["counts"]["shadow_rays"] == 0
    assert sorted(os.listdir(tmp_path / "renders")) == sorted(
        f"cam{c}_{o}{s}" for c in range(2) for o in ("depth", "mask") for s in (".npy", ".png", "_reference.npy"))


def test_time_renders_returns_the_cold_result_and_counts_repeats():
    calls = []
    result, timing = time_renders(lambda: calls.append(len(calls)) or len(calls), repeats=3, warmup=2)
    assert result == 1 and len(calls) == 6 and timing.repeats == 3 and timing.warmups == 2
    assert timing.warm_iqr_s >= 0 and timing.cold_s >= 0


def test_a_cold_render_that_spends_the_time_budget_leaves_no_warm_up_and_says_so():
    import time

    calls = []

    def render():
        calls.append(1)
        time.sleep(0.02 if len(calls) == 1 else 0.0)  # the cold render alone spends the budget
        return len(calls)

    _, timing = time_renders(render, repeats=3, warmup=2, max_seconds=0.01)
    assert len(calls) == 2 and timing.warmups == 0 and timing.repeats == 1  # the "warm" figure is the second render


@pytest.mark.parametrize("name", ("depth", "normals"))
def test_a_scene_without_shading_casts_the_pixel_centres_alone_whatever_its_spp(name):
    """Depth, mask and normal read sample 0 alone: samples 1..spp-1 would be rays (and normals) no output uses."""
    one = parse_scene(preset(name, width=8, height=6, spp=1))
    four = parse_scene(preset(name, width=8, height=6, spp=4))
    f1, c1 = render(AnalyticSphere(0.4), one, plan_passes(one), seed=2)
    f4, c4 = render(AnalyticSphere(0.4), four, plan_passes(four), seed=2)
    assert c4 == c1 and c4["primary_rays"] == len(four.cameras) * 8 * 6
    assert np.array_equal(f4.depth, f1.depth) and np.array_equal(f4.normal, f1.normal)


# ---- sampling of the integrator ------------------------------------------------------------------
def test_bounce_directions_are_cosine_weighted_about_the_normal():
    """cosine_directions: unit vectors in the normal's hemisphere with density cos θ / π, so P(cos θ > c) = 1 - c²
    and E[cos θ] = 2/3, with no preferred azimuth. The throughput update (times albedo, no cos/pdf factor) is only
    right for this density; the closed-form sphere test cannot see it (every direction hits the wall the same).
    Kills r = u for r = sqrt(u)."""
    from ddfbench.render.integrator import cosine_directions

    rng = np.random.default_rng(3)
    n = rng.normal(size=(200000, 3))
    n[:1000] = [0.0, 0.0, -1.0]  # the branch of the orthonormal basis for normals facing -z
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    d = cosine_directions(n, rng.random((len(n), 2))).astype(np.float64)
    cos = np.einsum("ij,ij->i", d, n)
    assert np.allclose(np.linalg.norm(d, axis=1), 1, atol=1e-6) and cos.min() >= 0
    assert abs(cos.mean() - 2 / 3) < 3e-3
    for c in (0.25, 0.5, 0.9):
        assert abs((cos > c).mean() - (1 - c * c)) < 5e-3
    for normal in ([0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.6, -0.48, 0.64]):  # no preferred azimuth about any normal
        fixed = np.tile(normal, (40000, 1))
        drawn = cosine_directions(fixed, rng.random((40000, 2))).astype(np.float64)
        tangent = drawn @ (np.eye(3) - np.outer(normal, normal))
        assert np.abs(tangent.mean(axis=0)).max() < 0.01


def test_an_escaping_bounce_sees_the_environment_through_the_albedo():
    """A floor lit by nothing (the one light shines from below) under an environment L: every bounce from its top
    escapes, so its path radiance is exactly ρ·L (ρ the throughput of the one bounce). Kills adding the
    environment without the path's throughput."""
    floor = trimesh.creation.box(extents=(1.1, 0.02, 1.1))
    rep = mesh_rep(floor)
    rho, env = 0.6, 0.5
    cfg = preset("path", width=24, height=24, spp=2, max_depth=2, albedo=rho, environment=env, background=0.0,
                 lights=[{"type": "directional", "direction": [0.0, 1.0, 0.0], "intensity": 1.0}],
                 cameras={"n": 1, "radius": 1.0, "elevation_deg": 70.0, "fov_deg": 30.0})
    scene = parse_scene(cfg)
    frames, counts = render(rep, scene, plan_passes(scene), seed=0)
    top = frames.mask[0] & (np.abs(frames.normal[0][..., 1] - 1.0) < 1e-4)
    assert top.sum() > 200 and counts["bounce_rays"] > 0
    assert np.allclose(frames.images["path"][0][top], rho * env, rtol=1e-5)


def test_the_shadow_share_of_a_pixel_averages_its_samples():
    """With spp > 1 a pixel across the shadow's edge is partly shadowed: the shadow image is the mean over the
    pixel's samples (some values strictly between 0 and 1), not the centre sample's 0 or 1."""
    floor = trimesh.creation.box(extents=(1.0, 0.02, 1.0))
    floor.apply_translation([0, -0.41, 0])
    ball = trimesh.creation.icosphere(4, 0.15)
    ball.apply_translation([0, -0.1, 0])
    cfg = preset("shaded", width=24, height=24, spp=8, albedo=0.5,
                 lights=[{"type": "directional", "direction": [0.0, -1.0, 0.0], "intensity": 2.0}],
                 cameras={"n": 1, "radius": 2.0, "elevation_deg": 60.0, "fov_deg": 35.0})
    scene = parse_scene(cfg)
    frames, _ = render(mesh_rep(trimesh.util.concatenate([floor, ball])), scene, plan_passes(scene), seed=0)
    shadow = frames.shadow[0]
    partial = (shadow > 0) & (shadow < 1)
    assert partial.sum() >= 3 and (shadow == 1).sum() >= 1
    assert np.allclose(shadow * 8, np.round(shadow * 8), atol=1e-5)  # eighths: one light, eight samples


def test_jittered_samples_spread_over_the_whole_pixel_about_its_centre():
    """Samples 1..spp-1 of a pixel are uniform over the pixel: their mean direction is the centre sample's, and they
    reach within a few % of its half-width. Kills an off-centre jitter (its mean leaves the pixel centre)."""
    w = h = 8
    cfg = preset("shaded", width=w, height=h, spp=64, cameras={"n": 1, "radius": 2.0, "elevation_deg": 0.0,
                                                               "fov_deg": 40.0})
    scene = parse_scene(cfg)
    _, d = primary_rays(scene, seed=2)
    d = d.astype(np.float64).reshape(64, h, w, 3)
    cam = scene.cameras[0]
    forward = (cam.look_at - cam.position) / np.linalg.norm(cam.look_at - cam.position)
    right = np.cross(forward, cam.up)
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    # image-plane coordinates in pixels: tan of the angle over the pixel's size in tan units
    pixel = 2 * math.tan(math.radians(40.0 / 2)) / h
    z = d @ forward
    px, py = (d @ right) / z / pixel, (d @ up) / z / pixel
    off_x, off_y = px[1:] - px[0], py[1:] - py[0]
    assert abs(off_x.mean()) < 0.02 and abs(off_y.mean()) < 0.02
    assert 0.45 < np.abs(off_x).max() <= 0.5 + 1e-4 and 0.45 < np.abs(off_y).max() <= 0.5 + 1e-4


def test_the_mesh_bvh_casts_on_the_threads_a_render_records(tmp_path):
    """render_threads (compute_threads) is recorded beside the mesh's and the reference's frame times; open3d's
    cast_rays defaults to every core, so the BVH must be told the count or its figure is not what is recorded, and
    the record says on how many the reference cast (reference_threads: suite v1's records lack it)."""
    torch = pytest.importorskip("torch")
    rep = mesh_rep(trimesh.creation.icosphere(3, 0.4))
    real, seen = rep._oracle._scene, []

    class Spy:
        def cast_rays(self, rays, nthreads=0):
            seen.append(nthreads)
            return real.cast_rays(rays, nthreads=nthreads)

    rep._oracle._o3d_scene = Spy()
    saved = torch.get_num_threads()
    cfg = preset("depth", width=8, height=8, timing={"repeats": 1, "warmup": 0})
    try:
        for threads in (1, 2):
            torch.set_num_threads(threads)
            seen.clear()
            hits = rep.intersect(np.array([[0.0, 0.0, 2.0]]), np.array([[0.0, 0.0, -1.0]]))
            assert hits.hit[0] and seen and all(n == threads for n in seen)
            seen.clear()
            cost = render_scene(mesh_rep(trimesh.creation.icosphere(1, 0.4)), rep, cfg, str(tmp_path), seed=0)["cost"]
            assert cost["reference_threads"] == cost["render_threads"] == threads and set(seen) == {threads}
    finally:
        torch.set_num_threads(saved)
