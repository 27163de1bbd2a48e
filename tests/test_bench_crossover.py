"""Section 12 of the bench: meshes of a given triangle count, the log-log crossover, and a small run."""

import math

import numpy as np
import pytest

from ddfbench.bench.context import Context
from ddfbench.bench.crossover import crossover, depth_error, mesh_with_faces, run
from ddfbench.bench.sizes import SIZES
from ddfbench.truth.oracle import Oracle


def test_subdivided_meshes_keep_the_surface_and_decimated_ones_shrink(sphere):
    base = sphere.mesh
    bigger = mesh_with_faces(base, 4 * len(base.faces) + 1)
    assert len(bigger.faces) == 16 * len(base.faces)  # two midpoint passes
    assert bigger.area == pytest.approx(base.area, rel=1e-9)  # midpoints of flat triangles: the same surface
    rng = np.random.default_rng(0)
    o = rng.uniform(-0.3, 0.3, (500, 3)) * [1, 1, 0] + [0, 0, -0.6]
    d = np.tile([0.0, 0.0, 1.0], (500, 1))
    t_base, t_big = Oracle(base).hit_distance(o, d), Oracle(bigger).hit_distance(o, d)
    np.testing.assert_allclose(t_big, t_base, atol=1e-5)
    smaller = mesh_with_faces(base, len(base.faces) // 4)
    assert len(smaller.faces) <= len(base.faces) // 4 + 2


def test_the_crossover_is_interpolated_log_log_between_the_bracketing_counts():
    # ratio 2 at 1e3, 0.5 at 1e5: log ratio falls linearly in log count, 1 halfway: 1e4
    assert crossover([1e2, 1e3, 1e5], [4.0, 2.0, 0.5]) == pytest.approx(1e4)
    assert crossover([1e3, 1e5], [0.5, 2.0]) == pytest.approx(1e4)  # rising works the same
    assert crossover([1e3, 1e4], [2.0, 3.0]) is None
    assert crossover([1e3, 1e4], [1.0, 3.0]) == pytest.approx(1e3)


def test_depth_error_counts_only_rays_both_hit():
    t = np.array([1.0, 2.0, np.inf, 4.0])
    ref = np.array([1.5, 2.0, 3.0, np.inf])
    err = depth_error(t, ref)
    assert err["depth_mae"] == pytest.approx(0.25) and err["hit_flip_share"] == pytest.approx(0.5)


def test_a_small_run_gives_a_row_per_count_model_and_ray_set(tmp_path):
    sizes = SIZES["small"]["crossover"]
    res = run(Context("cpu", sizes, repeats=1, warmup=0, workdir=str(tmp_path), threads=1))
    counts = res.details["counts"]
    assert len(counts) == len(sizes["counts"]) and counts == sorted(counts)
    assert len(res.rows) == len(counts) * len(sizes["models"]) * 2
    assert all(r.ratio > 0 and math.isfinite(r.ratio) for r in res.rows)
    for kind in ("primary", "incoherent"):
        entries = res.details[kind]
        subdivided = [e for e in entries if e["faces"] > res.details["shape_faces"]]
        assert subdivided and all(e["depth_mae"] < 1e-5 and e["hit_flip_share"] < 0.01 for e in subdivided)
        for name in sizes["models"]:
            found = res.details["crossover"][f"{name}, {kind}"]
            assert len(found["bvh_over_ddf"]) == len(counts)
