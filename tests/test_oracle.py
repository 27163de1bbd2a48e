"""The oracle against analytic shapes and its two ray-cast backends against each other."""

import numpy as np
import pytest

from ddfbench.oracle import Oracle
from ddfbench.shapes import load_shape
from tests.conftest import random_rays


def test_backends_agree_on_random_rays(bunny, rng):
    o, d = random_rays(rng, 20000)
    t1, tri1, n1 = Oracle(bunny.mesh, "open3d").first_hit(o, d)
    t2, tri2, n2 = Oracle(bunny.mesh, "embree").first_hit(o, d)
    assert np.array_equal(Oracle(bunny.mesh, "open3d").hit_distance(o, d), t1)
    assert np.array_equal(Oracle(bunny.mesh, "embree").hit_distance(o, d), t2)
    hit1, hit2 = np.isfinite(t1), np.isfinite(t2)
    assert hit1.mean() > 0.1
    assert (hit1 != hit2).mean() < 1e-3
    both = hit1 & hit2
    assert np.abs(t1[both] - t2[both]).max() < 1e-4
    same = both & (tri1 == tri2)  # open3d's own normals and the mesh's face normals, both turned to face the ray
    assert same.mean() > 0.09 and np.abs(n1[same] - n2[same]).max() < 1e-4
    assert np.all((n1 * d).sum(1)[hit1] < 0) and np.all(n1[~hit1] == 0) and np.all(n2[~hit2] == 0)


def test_first_hit_on_sphere_is_analytic(sphere, rng):
    o, d = random_rays(rng, 5000, half=0.2)  # inside the sphere: always one hit
    t, tri, n = Oracle(sphere.mesh).first_hit(o, d)
    b = (o * d).sum(1)
    exact = -b + np.sqrt(b * b - ((o * o).sum(1) - 0.25))
    assert np.all(tri >= 0)
    assert np.abs(t - exact).max() < 2e-3  # icosphere facets vs the analytic sphere
    assert np.all((n * d).sum(1) <= 0)  # normals face the ray
    assert np.allclose(np.linalg.norm(n, axis=1), 1, atol=1e-5)


@pytest.mark.parametrize("backend", ["open3d", "embree"])
def test_miss_is_inf(backend):
    box = load_shape({"name": "cube"})
    t, tri, n = Oracle(box.mesh, backend).first_hit(np.array([[2.0, 2.0, 2.0]]), np.array([[1.0, 0.0, 0.0]]))
    assert np.isinf(t[0]) and tri[0] == -1 and np.all(n[0] == 0)


@pytest.mark.parametrize("name", ["sphere", "cube"])
def test_signed_distance_analytic(name, rng):
    shape = load_shape({"name": name})
    p = rng.uniform(-0.6, 0.6, (4000, 3))
    sd = Oracle(shape.mesh).signed_distance(p)
    if name == "sphere":
        exact = np.linalg.norm(p, axis=1) - 0.5
        tol = 3e-3
    else:
        q = np.abs(p) - 0.5
        exact = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)
        tol = 1e-5
    assert np.abs(sd - exact).max() < tol


def test_occupancy_survives_a_hole():
    open_box = load_shape({"name": "open_box"})
    orc = Oracle(open_box.mesh, occupancy_rays=9)
    inside = np.array([[0.0, 0.0, 0.0], [0.2, -0.2, -0.3], [0.1, 0.3, 0.0]])
    outside = np.array([[0.0, 0.0, -0.55], [0.55, 0.0, 0.0], [0.0, 0.58, 0.2]])
    assert orc.occupancy(inside).all()
    assert not orc.occupancy(outside).any()


def test_closest_point_and_crossings(sphere, rng):
    orc = Oracle(sphere.mesh)
    p = rng.normal(size=(500, 3))
    cp, tri = orc.closest_point(p)
    assert np.abs(np.linalg.norm(cp, axis=1) - 0.5).max() < 3e-3
    assert np.all(tri >= 0)
    far = np.tile([[-1.0, 0.0123, 0.0311]], (3, 1))  # off vertices and edges
    d = np.array([[1.0, 0, 0], [1.0, 0, 0], [0, 1.0, 0]])
    assert list(orc.count_crossings(far, d)) == [2, 2, 0]


def test_any_hit_agrees_with_first_hit(sphere, rng):
    """any_hit is true exactly where a ray meets the sphere (rays from outside and inside, both ways)."""
    orc = Oracle(sphere.mesh)
    o = rng.uniform(-0.9, 0.9, size=(4000, 3))
    d = rng.normal(size=(4000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    hit = orc.any_hit(o, d)
    assert hit.dtype == bool and hit.shape == (4000,)
    assert 0.1 < hit.mean() < 0.9  # both outcomes occur
    assert np.array_equal(hit, np.isfinite(orc.hit_distance(o, d)))
    assert np.array_equal(hit, orc.count_crossings(o, d) > 0)


def test_warp_backend_without_warp_names_the_install(monkeypatch):
    """Where the `gpu` extra is missing, choosing the warp backend is a one-line error with the install command."""
    import sys

    from ddfbench.errors import InputError

    monkeypatch.setitem(sys.modules, "warp", None)  # import warp -> ImportError
    monkeypatch.delitem(sys.modules, "ddfbench.warp_cast", raising=False)
    with pytest.raises(InputError, match=r'pip install -e "\.\[gpu\]"') as err:
        Oracle(load_shape({"name": "cube"}).mesh, "warp")
    assert "\n" not in str(err.value)
