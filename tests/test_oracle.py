"""The oracle against analytic shapes and its two ray-cast backends against each other."""

import numpy as np
import pytest

from ddfbench.truth.oracle import Oracle
from ddfbench.truth.shapes import load_shape
from tests.conftest import random_rays
from tests.hard_cases.conftest import backend_params, has_warp

ALL_QUERIES = backend_params("open3d", "warp")  # backends that answer every query themselves


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


@pytest.mark.parametrize("backend", backend_params("open3d", "embree", "warp"))
def test_miss_is_inf(backend):
    box = load_shape({"name": "cube"})
    t, tri, n = Oracle(box.mesh, backend).first_hit(np.array([[2.0, 2.0, 2.0]]), np.array([[1.0, 0.0, 0.0]]))
    assert np.isinf(t[0]) and tri[0] == -1 and np.all(n[0] == 0)


@pytest.mark.parametrize("backend", ALL_QUERIES)
@pytest.mark.parametrize("name", ["sphere", "cube"])
def test_signed_distance_analytic(name, backend, rng):
    shape = load_shape({"name": name})
    p = rng.uniform(-0.6, 0.6, (4000, 3))
    sd = Oracle(shape.mesh, backend).signed_distance(p)
    if name == "sphere":
        exact = np.linalg.norm(p, axis=1) - 0.5
        tol = 3e-3
    else:
        q = np.abs(p) - 0.5
        exact = np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)
        tol = 1e-5
    assert np.abs(sd - exact).max() < tol


@pytest.mark.parametrize("backend", ALL_QUERIES)
def test_occupancy_survives_a_hole(backend):
    open_box = load_shape({"name": "open_box"})
    orc = Oracle(open_box.mesh, backend, occupancy_rays=9)
    inside = np.array([[0.0, 0.0, 0.0], [0.2, -0.2, -0.3], [0.1, 0.3, 0.0]])
    outside = np.array([[0.0, 0.0, -0.55], [0.55, 0.0, 0.0], [0.0, 0.58, 0.2]])
    assert orc.occupancy(inside).all()
    assert not orc.occupancy(outside).any()


@pytest.mark.parametrize("backend", ALL_QUERIES)
def test_closest_point_and_crossings(sphere, backend, rng):
    orc = Oracle(sphere.mesh, backend)
    p = rng.normal(size=(500, 3))
    cp, tri = orc.closest_point(p)
    assert np.abs(np.linalg.norm(cp, axis=1) - 0.5).max() < 3e-3
    assert np.all(tri >= 0)
    far = np.tile([[-1.0, 0.0123, 0.0311]], (3, 1))  # off vertices and edges
    d = np.array([[1.0, 0, 0], [1.0, 0, 0], [0, 1.0, 0]])
    assert list(orc.count_crossings(far, d)) == [2, 2, 0]


@pytest.mark.parametrize("backend", ALL_QUERIES)
def test_any_hit_agrees_with_first_hit(sphere, backend, rng):
    """any_hit is true exactly where a ray meets the sphere (rays from outside and inside, both ways)."""
    orc = Oracle(sphere.mesh, backend)
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

    from ddfbench.core.errors import InputError

    monkeypatch.setitem(sys.modules, "warp", None)  # import warp -> ImportError
    monkeypatch.delitem(sys.modules, "ddfbench.truth.warp_cast", raising=False)
    with pytest.raises(InputError, match=r'pip install -e "\.\[gpu\]"') as err:
        Oracle(load_shape({"name": "cube"}).mesh, "warp")
    assert "\n" not in str(err.value)


@pytest.mark.skipif(not has_warp(), reason='NVIDIA Warp not installed (pip install -e ".[gpu]")')
def test_warp_point_queries_and_crossings_equal_open3d_on_the_bunny(bunny, rng):
    """Distances, inside tests and crossing counts through Warp equal open3d's on a scanned mesh; a closest
    point may differ only where two surface points are equally near (same distance)."""
    a, w = Oracle(bunny.mesh, "open3d"), Oracle(bunny.mesh, "warp")
    p = rng.uniform(-0.55, 0.55, (5000, 3))
    dist = a.unsigned_distance(p)
    assert np.abs(w.unsigned_distance(p) - dist).max() < 1e-6
    assert np.array_equal(w.occupancy(p, seed=4), a.occupancy(p, seed=4))
    cp, tri = w.closest_point(p)
    assert np.all(tri >= 0) and np.abs(np.linalg.norm(cp - p, axis=1) - dist).max() < 1e-6
    o, d = random_rays(rng, 5000)
    crossings = a.count_crossings(o, d)
    assert crossings.max() >= 3 and np.array_equal(w.count_crossings(o, d), crossings)
    assert np.array_equal(w.any_hit(o, d), a.any_hit(o, d))


@pytest.mark.skipif(not has_warp(), reason='NVIDIA Warp not installed (pip install -e ".[gpu]")')
def test_warp_oracle_needs_no_open3d(tmp_path):
    """With open3d not importable (a GPU machine gets only small wheels), the warp oracle answers every query."""
    import subprocess
    import sys

    script = (
        "import sys; sys.modules['open3d'] = None\n"
        "import numpy as np\n"
        "from ddfbench.truth.oracle import Oracle\n"
        "from ddfbench.truth.shapes import load_shape\n"
        "orc = Oracle(load_shape({'name': 'sphere'}).mesh, 'warp')\n"
        "p = np.array([[0.0, 0.0, 0.0], [0.9, 0.0, 0.0]]); d = np.array([[1.0, 0.0, 0.0]] * 2)\n"
        "print(orc.signed_distance(p).astype(float).round(2).tolist(), orc.hit_distance(p, d).astype(float).round(2).tolist(),\n"
        "      orc.count_crossings(p - [[1.0, 0, 0]], d).tolist(), orc.any_hit(p, d).tolist())\n"
        "from ddfbench.core.errors import InputError\n"
        "for backend, query in (('open3d', 'hit_distance'), ('embree', 'count_crossings')):\n"
        "    try:\n"
        "        getattr(Oracle(orc.mesh, backend), query)(p, d)\n"
        "    except InputError as err:\n"
        "        assert '\\n' not in str(err) and 'oracle.backend=warp' in str(err), err\n"
        "        print('open3d blocked')\n"
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    lines = out.stdout.strip().splitlines()
    assert lines[-3:] == ["[-0.5, 0.4] [0.5, inf] [2, 1] [True, False]", "open3d blocked", "open3d blocked"]


def test_embree_pool_equals_the_embree_oracle(bunny, rng):
    """embreex in worker processes (Embree on every core without open3d) gives the single-process answers, the
    empty call included; the pool is built with every worker started (3 workers on 2 cores)."""
    from ddfbench.truth.embree_pool import EmbreePool

    o, d = random_rays(rng, 20001)
    pool = EmbreePool(bunny.mesh, workers=3)
    try:
        assert len(pool.pids) == 3
        t = pool.hit_distance(o, d)
        assert np.isfinite(t).mean() > 0.1
        assert np.array_equal(t, Oracle(bunny.mesh, "embree").hit_distance(o, d))
        assert pool.hit_distance(np.zeros((0, 3)), np.zeros((0, 3))).shape == (0,)
    finally:
        pool.close()
