"""Samplers: every label checked against the second ray-cast backend or trimesh, paper-literal options, bad input."""

import os

import numpy as np
import pytest
import trimesh

from ddfbench.core import plugins
from ddfbench.core.errors import InputError
from ddfbench.sampling import available_strategies, build
from ddfbench.sampling.collect import Collector
from ddfbench.sampling.directions import paper_eq10_directions, random_perpendicular, uniform_directions
from ddfbench.sampling.samples import Samples
from ddfbench.sampling.steps import marching_distances
from ddfbench.sampling.triangles import barycentric, face_plan
from ddfbench.truth.oracle import Oracle
from ddfbench.truth.shapes import Shape, load_shape


def config(strategy, **overrides):
    """conf/sampling/<strategy>.yaml (its config, not the experiments it joins) with the field box
    resolved and overrides applied."""
    cfg = plugins.defaults("sampling", strategy)
    cfg["box"] = 0.6
    cfg.update(overrides)
    return cfg


@pytest.fixture(scope="module")
def cow():
    return load_shape({"name": "cow"})


def recheck_rays(shape, samples, rng, n=4000):
    """Re-cast a random subset with the embree backend: finite labels within 1e-4, inf labels true misses."""
    idx = rng.choice(len(samples), min(n, len(samples)), replace=False)
    t_ref, _, _ = Oracle(shape.mesh, "embree").first_hit(samples.x[idx], samples.d[idx])
    t = samples.t[idx]
    assert np.array_equal(samples.hit, np.isfinite(samples.t))
    assert np.all(np.isfinite(t_ref[~np.isfinite(t)]) == False)  # noqa: E712  every inf label is a miss
    assert np.all(np.isfinite(t_ref[np.isfinite(t)]))
    fin = np.isfinite(t)
    assert np.abs(t[fin] - t_ref[fin]).max() <= 1e-4
    assert np.allclose(np.linalg.norm(samples.d, axis=1), 1, atol=1e-5)
    return fin.mean()


RAY_CASES = [
    ("surface", {}),
    ("surface", {"face_mode": "per_face", "s_fc": 1, "s_dr": 3, "s_p": 3, "steps": "geometric"}),
    ("surface", {"steps": "uniform", "directions": "paper_eq10", "barycentric": "paper_eq9"}),
    ("random", {"n_samples": 20000}),
    ("pov", {"resolution": 24}),
    ("pov", {"resolution": 16, "s_p": 3, "steps": "geometric"}),
]


@pytest.mark.parametrize("strategy,overrides", RAY_CASES)
def test_ray_labels_agree_with_second_backend(cow, rng, tmp_path, strategy, overrides):
    samples, path, info = build(cow, Oracle(cow.mesh), config(strategy, **overrides), "rays", 0, str(tmp_path))
    hit_share = recheck_rays(cow, samples, rng)
    assert 0.05 < hit_share < 0.95  # both hits and misses are present
    assert np.abs(samples.x).max() <= 0.6 + 1e-6
    assert info["n_samples"] == len(samples) and info["memory_bytes"] > 0 and info["sampling_s"] > 0


@pytest.mark.parametrize("strategy,overrides", [("surface", {"s_dr": 4, "s_p": 4}), ("random", {"n_samples": 20000}),
                                                 ("pov", {"resolution": 24}), ("pov", {"resolution": 16, "s_p": 3})])
def test_every_ray_sampler_labels_whole_lines_exactly(sphere, tmp_path, strategy, overrides):
    """line_hit: the line through x along d meets the sphere (|x - (x.d) d| <= radius), for every strategy,
    with both kinds present, true wherever the ray hits, and kept by the cache."""
    samples, path, info = build(sphere, Oracle(sphere.mesh), config(strategy, **overrides), "rays", 0, str(tmp_path))
    x, d = samples.x.astype(np.float64), samples.d.astype(np.float64)
    gap = np.linalg.norm(x - np.einsum("ij,ij->i", x, d)[:, None] * d, axis=1) - 0.5
    clear = np.abs(gap) > 0.01  # away from the tessellated sphere's tangent lines
    assert np.array_equal(samples.line_hit[clear], gap[clear] < 0)
    assert np.all(samples.line_hit[samples.hit])
    assert 100 < (~samples.line_hit).sum() == info["n_line_miss"] and samples.line_hit.sum() > 100
    assert np.array_equal(Samples.load_npz(path).line_hit, samples.line_hit)


def test_surface_rejects_rays_into_the_mesh_and_occluded_ones(cow, tmp_path):
    cfg = config("surface", face_mode="per_face", s_fc=1, s_dr=4, s_p=4, perpendicular=False)
    samples, _, info = build(cow, Oracle(cow.mesh), cfg, "rays", 0, str(tmp_path))
    rej = info["rejected"]
    candidates = len(cow.mesh.faces) * 16
    assert info["candidates"] == candidates
    # about half the directions point into a closed mesh; a non-convex cow occludes some more
    assert 0.4 < rej["inside"] / candidates < 0.6 and rej["occluded"] > 0
    kept = candidates - sum(rej.values())
    toward = samples.hit  # (p + t theta, -theta; t) samples; the others are the escape misses
    assert toward.sum() == kept and (~toward).sum() <= kept
    # a kept sample's label ray ends on the surface: its end point is (almost) on the mesh
    end = samples.x[toward] + samples.t[toward, None] * samples.d[toward]
    assert Oracle(cow.mesh).unsigned_distance(end[:2000]).max() < 1e-5


@pytest.mark.parametrize("strategy,overrides", [("surface", {}), ("random", {"n_samples": 3000}), ("pov", {"resolution": 8})])
def test_sdf_labels_agree_with_trimesh(rng, tmp_path, strategy, overrides):
    bone = load_shape({"name": "bone"})
    samples, path, info = build(bone, Oracle(bone.mesh), config(strategy, **overrides), "sdf", 0, str(tmp_path))
    assert samples.sdf is not None and samples.sdf.shape == (len(samples),)
    idx = rng.choice(len(samples), 300, replace=False)
    ref = -trimesh.proximity.signed_distance(bone.mesh, samples.x[idx].astype(np.float64))  # trimesh: + inside
    assert np.abs(samples.sdf[idx] - ref).max() < 1e-4
    assert (samples.sdf < 0).mean() > 0.005  # inside points are present (the bone fills ~2 % of the box)
    if strategy == "surface":  # narrow band: most points near the surface
        assert np.median(np.abs(samples.sdf)) < 0.03


def test_sdf_uniform_appends_box_points_to_the_same_narrow_band(rng, tmp_path):
    bone = load_shape({"name": "bone"})
    oracle = Oracle(bone.mesh)
    band, _, _ = build(bone, oracle, config("surface", sdf_uniform=0.0), "sdf", 0, str(tmp_path))
    mixed, _, info = build(bone, oracle, config("surface", sdf_uniform=0.25), "sdf", 0, str(tmp_path))
    n = len(band)
    assert np.array_equal(mixed.x[:n], band.x) and np.array_equal(mixed.sdf[:n], band.sdf)
    assert len(mixed) - n == info["uniform_labels"] == round(n / 3)  # a quarter of all labels
    tail = mixed.x[n:]
    assert np.all(np.abs(tail) <= 0.6) and np.all(tail.min(axis=0) < -0.55) and np.all(tail.max(axis=0) > 0.55)
    # uniform in the box: the bone fills ~2 % of it, and most box points lie beyond the narrow band
    assert (mixed.sdf[n:] < 0).mean() < 0.05 and np.median(np.abs(mixed.sdf[n:])) > 3 * 0.05
    idx = rng.choice(len(tail), 300, replace=False)
    ref = -trimesh.proximity.signed_distance(bone.mesh, tail[idx].astype(np.float64))
    assert np.abs(mixed.sdf[n:][idx] - ref).max() < 1e-4


def test_paper_eq9_leaves_the_triangle_default_does_not(rng):
    a, b = barycentric(rng, 200000, "paper_eq9")
    assert abs((a + b > 1).mean() - 0.5) < 0.01
    a, b = barycentric(rng, 200000, "uniform")
    assert (a + b > 1).sum() == 0
    # uniform over the area: the corner triangle a + b < 1/2 holds a quarter of the area
    assert abs((a + b < 0.5).mean() - 0.25) < 0.01


def test_paper_eq10_crowds_the_poles_default_does_not(rng):
    # caps |z| > 0.9 hold 10 % of the sphere's area; uniform angles put 2 arccos(0.9) / pi = 28.7 % there
    for rule, expected in ((paper_eq10_directions, 2 * np.arccos(0.9) / np.pi), (uniform_directions, 0.1)):
        d = rule(rng, 200000)
        assert np.allclose(np.linalg.norm(d, axis=1), 1, atol=1e-6)
        assert abs((np.abs(d[:, 2]) > 0.9).mean() - expected) < 0.005


def test_paper_eq9_points_off_the_surface_are_caught(cow, rng, tmp_path):
    cfg = config("surface", barycentric="paper_eq9")
    samples, _, info = build(cow, Oracle(cow.mesh), cfg, "rays", 0, str(tmp_path))
    assert info["rejected"]["verify"] > 0.05 * info["candidates"]  # their backward ray misses p
    recheck_rays(cow, samples, rng)


def test_perpendicular_directions(rng):
    d = uniform_directions(rng, 1000)
    u = random_perpendicular(rng, d)
    assert np.abs((u * d).sum(1)).max() < 1e-5
    assert np.allclose(np.linalg.norm(u, axis=1), 1, atol=1e-5)


@pytest.mark.parametrize("rule", ["uniform", "stratified", "geometric"])
def test_marching_distances_stay_in_range_and_ascend(rng, rule):
    hi = rng.uniform(0.01, 1.0, 500)
    t = marching_distances(rule, 8, 1e-3, hi, rng)
    assert t.shape == (500, 8)
    assert np.all(t >= 1e-3) and np.all(t <= hi[:, None] + 1e-12) and np.all(np.diff(t, axis=1) >= 0)
    if rule == "geometric":  # half the samples within the geometric middle of the range
        assert np.mean(t[:, 3] < np.sqrt(1e-3 * hi)) > 0.3


def test_face_plan_skips_zero_area_faces(rng):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 0, 0], [0, 0, 1]], float)
    f = np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4]])  # face 1 is degenerate (collinear)
    mesh = trimesh.Trimesh(v, f, process=False)
    per_face = face_plan(mesh, 3, "per_face", rng)
    assert sorted(per_face.tolist()) == [0, 0, 0, 2, 2, 2]
    total = face_plan(mesh, 1000, "total", rng)
    assert len(total) == 2000 and 1 not in total
    assert abs((total == 0).mean() - 0.5) < 0.05  # both faces have area 1/2


def test_open_mesh_still_samples_and_reports_rejections(rng, tmp_path):
    shape = load_shape({"name": "bunny10k"})
    samples, _, info = build(shape, Oracle(shape.mesh), config("surface"), "rays", 0, str(tmp_path))
    assert not shape.watertight and len(samples) > 0 and info["rejected"]["inside"] > 0
    recheck_rays(shape, samples, rng)


def test_cache_reuses_the_dataset(sphere, tmp_path):
    cfg = config("random", n_samples=1000)
    s1, p1, i1 = build(sphere, Oracle(sphere.mesh), cfg, "rays", 3, str(tmp_path))
    s2, p2, i2 = build(sphere, Oracle(sphere.mesh), cfg, "rays", 3, str(tmp_path))
    assert p1 == p2 and not i1["cache_hit"] and i2["cache_hit"]
    assert np.array_equal(s1.x, s2.x) and np.array_equal(s1.t, s2.t) and i2["n_samples"] == 1000
    _, p3, i3 = build(sphere, Oracle(sphere.mesh), cfg, "rays", 4, str(tmp_path))
    assert p3 != p1 and not i3["cache_hit"]
    _, p4, _ = build(sphere, Oracle(sphere.mesh), dict(cfg, n_samples=999), "rays", 3, str(tmp_path))
    assert p4 != p1
    loaded = Samples.load_npz(p1)
    with np.load(p1) as z:
        assert {"x", "d", "t", "hit"} <= set(z.files)
    assert loaded.meta["strategy"] == "random" and len(loaded) == 1000


@pytest.mark.parametrize("damage", ["cut", "garbled", "empty"])
def test_a_cached_dataset_that_cannot_be_read_is_built_anew_and_named(sphere, tmp_path, damage, caplog):
    cfg = config("random", n_samples=1000)
    first, path, _ = build(sphere, Oracle(sphere.mesh), cfg, "rays", 3, str(tmp_path))
    data = open(path, "rb").read()
    with open(path, "wb") as fh:  # a crash or a full disk cut it short; another writer garbled it
        fh.write({"cut": data[:len(data) // 2], "garbled": b"x" * len(data), "empty": b""}[damage])
    again, path2, info = build(sphere, Oracle(sphere.mesh), cfg, "rays", 3, str(tmp_path))
    assert path2 == path and not info["cache_hit"] and np.array_equal(again.t, first.t)
    assert f"{path}: not a readable dataset" in caplog.text
    assert build(sphere, Oracle(sphere.mesh), cfg, "rays", 3, str(tmp_path))[2]["cache_hit"]  # whole again
    assert sorted(os.listdir(tmp_path)) == [os.path.basename(path)]  # no temporary file left


@pytest.mark.parametrize("key,value", [("s_fc", 0), ("s_dr", 2.5), ("s_p", -1), ("s_fc", True), ("steps", "spiral"),
                                       ("t_min", 0), ("face_mode", "some"),
                                       ("sdf_uniform", 1.0), ("sdf_uniform", -0.1), ("sdf_uniform", "half")])
def test_bad_surface_values(sphere, tmp_path, key, value):
    with pytest.raises(InputError, match=f"sampling.{key}"):
        build(sphere, Oracle(sphere.mesh), config("surface", **{key: value}), "rays", 0, str(tmp_path))


def test_unknown_strategy_lists_the_available_ones(sphere, tmp_path):
    assert available_strategies() == ["pov", "random", "surface"]
    with pytest.raises(InputError, match="pov, random, surface"):
        build(sphere, Oracle(sphere.mesh), {"strategy": "spiral"}, "rays", 0, str(tmp_path))


def test_unknown_and_missing_keys(sphere, tmp_path):
    with pytest.raises(InputError, match="unknown key.*s_pp"):
        build(sphere, Oracle(sphere.mesh), config("surface", s_pp=3), "rays", 0, str(tmp_path))
    cfg = config("surface")
    del cfg["s_p"]
    with pytest.raises(InputError, match="missing key.*s_p"):
        build(sphere, Oracle(sphere.mesh), cfg, "rays", 0, str(tmp_path))


def test_camera_inside_the_shape(sphere, tmp_path):
    with pytest.raises(InputError, match="inside shape sphere"):
        build(sphere, Oracle(sphere.mesh), config("pov", radius=0.2, resolution=4), "rays", 0, str(tmp_path))


def test_every_ray_rejected_is_an_error(sphere, tmp_path):
    # a field box smaller than the sphere: every surface point lies outside it
    with pytest.raises(InputError, match="no samples.*outside_box"):
        build(sphere, Oracle(sphere.mesh), config("surface", box=0.2), "rays", 0, str(tmp_path))


def test_too_many_samples_is_an_error(sphere, tmp_path):
    with pytest.raises(InputError, match="max_samples"):
        build(sphere, Oracle(sphere.mesh), config("surface", max_samples=1000), "rays", 0, str(tmp_path))
    assert not os.listdir(tmp_path)


def test_collector_keeps_every_label_past_its_reservation_and_stops_at_the_cap(rng):
    out = Collector(20, "test sampling")
    out.expect(3, "rays", most=4)  # a reservation the sampler then outgrows
    parts = [rng.random((k, 3), dtype=np.float32) for k in (3, 5, 6)]
    for p in parts:
        out.add(p, -p, np.where(p[:, 0] > 0.5, np.inf, p[:, 1]).astype(np.float32))
    got = out.samples()
    want = np.concatenate(parts)
    assert np.array_equal(got.x, want) and np.array_equal(got.d, -want)
    assert np.array_equal(got.hit, want[:, 0] <= 0.5) and got.sdf is None
    sdf = Collector(20, "test sampling")
    sdf.add(parts[0], sdf=parts[0][:, 0])
    assert sdf.samples().d is None
    full = Collector(10, "test sampling")
    full.add(parts[2], -parts[2], parts[2][:, 0])
    with pytest.raises(InputError, match="test sampling would give about 24 samples.*max_samples=10"):
        full.add(parts[2], -parts[2], parts[2][:, 0], done=0.5)


def test_zero_area_faces_of_an_unvalidated_mesh_are_never_sampled(rng, tmp_path):
    box = trimesh.creation.box(extents=(0.8, 0.8, 0.8))
    v = np.vstack([box.vertices, [[0.4, 0.4, 0.4]]])  # a sliver face: two corners and a repeated corner
    f = np.vstack([box.faces, [[0, 0, 1]]])
    mesh = trimesh.Trimesh(v, f, process=False)
    shape = Shape(mesh=mesh, name="box_sliver", source="test", transform={"center": [0, 0, 0], "scale": 1.0},
                  watertight=False)
    cfg = config("surface", face_mode="per_face", s_fc=5)
    samples, _, info = build(shape, Oracle(mesh), cfg, "rays", 0, str(tmp_path))
    assert info["n_points"] == 5 * 12
    recheck_rays(shape, samples, rng)


def _build_in_process(cache_dir):
    shape = load_shape({"name": "sphere"})
    return build(shape, Oracle(shape.mesh), config("random", n_samples=20000), "rays", 0, cache_dir)[1]


@pytest.mark.slow
def test_two_processes_building_one_dataset_leave_one_complete_file(tmp_path):
    """Two runs that need the same dataset at once (a sweep under a parallel launcher) both build it;
    the cache ends with one complete file and no temporaries."""
    import multiprocessing

    with multiprocessing.get_context("spawn").Pool(2) as pool:
        paths = pool.map(_build_in_process, [str(tmp_path)] * 2)
    assert paths[0] == paths[1] and os.listdir(tmp_path) == [os.path.basename(paths[0])]
    assert len(Samples.load_npz(paths[0])) == 20000


def test_a_label_subset_keeps_every_label_of_the_rows_it_draws():
    n = 50
    rng = np.random.default_rng(0)
    full = Samples(x=rng.random((n, 3), dtype=np.float32), d=rng.random((n, 3), dtype=np.float32),
                   t=np.arange(n, dtype=np.float32), hit=np.arange(n) % 2 == 0, line_hit=np.arange(n) % 3 != 1,
                   sdf=np.arange(n, dtype=np.float32) - 25, meta={"strategy": "test"})
    sub = full.subset(20, np.random.default_rng(1))
    rows = sub.t.astype(int)  # t numbers the rows: every other array must come from the same ones
    assert len(sub) == 20 and len(set(rows)) == 20
    assert np.array_equal(sub.x, full.x[rows]) and np.array_equal(sub.d, full.d[rows])
    assert np.array_equal(sub.hit, rows % 2 == 0) and np.array_equal(sub.line_hit, rows % 3 != 1)
    assert np.array_equal(sub.sdf, rows - 25.0) and sub.meta == {"strategy": "test"}
    assert Samples(x=full.x, sdf=full.sdf).subset(5, np.random.default_rng(1)).line_hit is None


def test_a_dataset_key_names_a_caster_other_than_open3d_and_keeps_open3ds_committed_keys():
    from ddfbench.report import compact
    from ddfbench.sampling.cache import dataset_key

    rec = compact.load_records("reports/sampling/records.jsonl.gz", strict=True)[0]  # an open3d run's dataset
    assert rec["config"]["oracle"]["backend"] == "open3d"
    shape = load_shape(rec["config"]["shape"])
    keys = {backend: dataset_key(shape, Oracle(shape.mesh, backend), rec["config"]["sampling"],
                                 rec["sampling"]["kind"], rec["config"]["seed"]) for backend in ("open3d", "embree")}
    assert rec["artifacts"]["dataset"].endswith(f"-{keys['open3d']}.npz")  # the key its record names
    assert keys["embree"] != keys["open3d"]  # a warp or embree draw is not served to an open3d run


@pytest.mark.parametrize("rule", ["stratified", "geometric"])
def test_marching_distances_draw_once_in_each_stratum(rng, rule):
    """stratified: column k in [lo + k/s_p (hi - lo), lo + (k+1)/s_p (hi - lo)]; geometric: the same strata of the
    log distance, [lo (hi/lo)^(k/s_p), lo (hi/lo)^((k+1)/s_p)]. Kills a warped geometric exponent (frac squared) and
    strata that are not equal, which the range and order checks above let through."""
    lo, hi, s_p = 1e-3, rng.uniform(0.05, 1.0, 2000), 5
    t = marching_distances(rule, s_p, lo, hi, rng)
    k = np.arange(s_p)
    if rule == "stratified":
        lower, upper = lo + k / s_p * (hi[:, None] - lo), lo + (k + 1) / s_p * (hi[:, None] - lo)
    else:
        lower, upper = lo * (hi[:, None] / lo) ** (k / s_p), lo * (hi[:, None] / lo) ** ((k + 1) / s_p)
    assert np.all(t >= lower * (1 - 1e-12)) and np.all(t <= upper * (1 + 1e-12))
    # and uniform within its stratum: the draw sits in the stratum's lower half about half the time
    mid = (lower + upper) / 2 if rule == "stratified" else np.sqrt(lower * upper)
    assert abs((t < mid).mean() - 0.5) < 0.03


def test_perpendicular_misses_go_both_ways_about_the_escaping_ray(sphere, tmp_path):
    """An escaping ray (x, theta; inf) also gives (x, u; inf) and (x, -u; inf), u perpendicular to theta (the paper's
    theta +- pi/2; on a sphere from outside, both miss only where the ray leaves the sphere's tangent region, so some
    x keep both). Kills casting the same side twice."""
    cfg = config("surface", s_dr=4, s_p=4, perpendicular=True)
    samples, _, _ = build(sphere, Oracle(sphere.mesh), cfg, "rays", 0, str(tmp_path))
    miss = ~samples.hit
    x, d = samples.x[miss], samples.d[miss].astype(np.float64)
    _, group, count = np.unique(x, axis=0, return_inverse=True, return_counts=True)
    group = group.ravel()
    triples = np.flatnonzero(count == 3)
    assert len(triples) > 50 and count.max() == 3
    order = np.argsort(group, kind="stable")  # each x's labels in the order written: escape, +u, -u
    rows = order[np.isin(group[order], triples)].reshape(-1, 3)
    theta, plus, minus = d[rows[:, 0]], d[rows[:, 1]], d[rows[:, 2]]
    assert np.abs((theta * plus).sum(1)).max() < 1e-5 and np.abs(plus + minus).max() < 1e-5


def test_a_marching_distance_below_the_least_height_is_rejected_as_grazing(sphere, tmp_path):
    """A sample less than TOL above its face plane is rejected (`grazing`): with t_min 1e-7 and geometric steps many
    first steps are that close. Kills a grazing test that never fires."""
    cfg = config("surface", face_mode="per_face", s_fc=1, s_dr=2, s_p=4, steps="geometric", t_min=1e-7,
                 perpendicular=False)
    samples, _, info = build(sphere, Oracle(sphere.mesh), cfg, "rays", 0, str(tmp_path))
    assert info["rejected"]["grazing"] > 0.05 * info["candidates"]
    assert samples.t[samples.hit].min() >= 1e-5


def test_pov_marching_samples_crowd_toward_the_hit(sphere, tmp_path):
    """pov with s_p > 0 places its samples back from the first hit by the steps rule: with geometric steps from
    t_min 1e-3 most hit labels are short (the log strata put half the draws within sqrt(t_min t_hit) of the hit).
    Kills placing them forward from the box entry (labels then run nearly the whole way to the hit)."""
    cfg = config("pov", resolution=16, s_p=4, steps="geometric")
    samples, _, _ = build(sphere, Oracle(sphere.mesh), cfg, "rays", 0, str(tmp_path))
    t = samples.t[samples.hit]
    assert len(t) > 1000 and np.median(t) < 0.02


def test_sdf_sigmas_cycle_within_each_surface_points_offsets(rng, tmp_path):
    """Each surface point's s_dr x s_p offsets cycle through sdf_sigmas (rows alternate 1e-4, 0.05 here), so the band
    is the same everywhere on the surface. Kills np.repeat for np.tile (the first points all get the small sigma)."""
    cfg = config("surface", face_mode="per_face", s_fc=1, s_dr=1, s_p=2, sdf_sigmas=[1e-4, 0.05], sdf_uniform=0.0,
                 box=1.0)
    sphere = load_shape({"name": "sphere"})
    samples, _, info = build(sphere, Oracle(sphere.mesh), cfg, "sdf", 0, str(tmp_path))
    assert info["rejected"].get("outside_box", 0) == 0 and len(samples) == 2 * info["n_points"]
    near, far = np.abs(samples.sdf[0::2]), np.abs(samples.sdf[1::2])
    assert np.median(near) < 5e-4 and np.median(far) > 0.01
    assert np.median(near[: len(near) // 2]) < 5e-4 and np.median(far[: len(far) // 2]) > 0.01


def test_surface_labels_are_exact_for_the_stored_float32_rays(sphere, tmp_path):
    """A kept label is the distance from the stored (float32) x back along the stored d to the plane of the face the
    ray was cast from: near grazing incidence, rounding x to float32 after labelling it in float64 moved the end of
    the label ray off the surface by up to 6e-5 (the label is t for p + t theta in float64, not for the x stored)."""
    cfg = config("surface", s_dr=4, s_p=4, perpendicular=False)
    samples, _, _ = build(sphere, Oracle(sphere.mesh), cfg, "rays", 0, str(tmp_path))
    hit = np.flatnonzero(samples.hit)
    x, d, t = (a[hit].astype(np.float64) for a in (samples.x, samples.d, samples.t))
    _, tri, _ = Oracle(sphere.mesh).first_hit(samples.x[hit], samples.d[hit])
    v0, n = np.asarray(sphere.mesh.vertices)[sphere.mesh.faces[tri, 0]], np.asarray(sphere.mesh.face_normals)[tri]
    t_plane = np.einsum("ij,ij->i", v0 - x, n) / np.einsum("ij,ij->i", d, n)  # float64 distance to the hit face's plane
    assert np.abs(t - t_plane).max() < 2e-6
