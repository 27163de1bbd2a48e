"""Case 2: grazing rays (tangent to a sphere, in a face's plane, at 1, 0.1, 0.01 degrees to a plane).

Promise, for every exact ray caster (oracle open3d / embree / warp, mesh family on open3d / warp):
- never a NaN: a hit has finite t >= 0 and a unit normal, a miss has t = inf and a zero normal;
- a ray tangent to the icosphere's circumsphere misses (the facets lie inside it); 1e-3 inside it hits;
- a ray lying exactly in a face's plane never reports the coplanar face: it hits the neighbouring
  face at their shared edge, the same t as a ray 1e-6 below the plane, or misses like one 1e-6 above;
- a ray at angle a to a plane hits at t = h / sin(a) with relative error below 1e-3 down to 0.01 degrees.
"""

import numpy as np
import pytest

from tests.hard_cases.conftest import assert_well_formed, backend_params, hard_shape, ray_backends, unit

BACKENDS = backend_params("oracle-open3d", "oracle-embree", "oracle-warp", "mesh-family", "mesh-family-warp")


@pytest.fixture(scope="module")
def sphere_casters(sphere):
    return ray_backends(sphere.mesh)


@pytest.fixture(scope="module")
def cube_casters(cube):
    return ray_backends(cube.mesh)


def tangent_rays(rng, n, offset):
    """Rays (origins, unit directions) passing at distance `offset` from the origin, starting 1 before closest approach."""
    d = unit(rng.normal(size=(n, 3)))
    perp = unit(np.cross(d, rng.normal(size=(n, 3))))
    return offset * perp - d, d


@pytest.mark.parametrize("name", BACKENDS)
def test_sphere_tangent_and_just_inside(sphere_casters, name):
    cast = sphere_casters[name]
    rng = np.random.default_rng(3)
    for offset, expect_hit in [(0.5, False), (0.5 - 1e-9, False), (0.499, True)]:
        o, d = tangent_rays(rng, 5000, offset)
        t, hit, n = cast(o, d)
        assert_well_formed(t, hit, n)
        assert np.all(hit == expect_hit), f"{name}: offset {offset}: {hit.mean():.3f} hit"


@pytest.mark.parametrize("name", BACKENDS)
def test_ray_in_a_face_plane_is_its_neighbour_below(cube_casters, name):
    cast = cube_casters[name]
    xy = np.array([[-1.0, 0.1], [-1.0, -0.45], [0.0, 0.1], [0.3, -0.2]])  # from outside, and from on the face
    d = np.tile([[1.0, 0.0, 0.0]], (len(xy), 1))
    on = np.c_[xy, np.full(len(xy), 0.5)]
    t_on, hit_on, n_on = cast(on, d)
    t_below, hit_below, _ = cast(on - [0, 0, 1e-6], d)
    t_above, hit_above, _ = cast(on + [0, 0, 1e-6], d)
    assert_well_formed(t_on, hit_on, n_on)
    assert hit_on.all() and hit_below.all() and not hit_above.any()
    t_exact = np.where(xy[:, 0] < -0.5, -0.5, 0.5) - xy[:, 0]  # the side face it enters or leaves by
    assert np.allclose(t_on, t_exact, atol=1e-6) and np.allclose(t_on, t_below, atol=1e-6)
    assert np.allclose(np.abs(n_on[:, 0]), 1.0), "a coplanar ray must not report the face it lies in"


@pytest.mark.parametrize("degrees", [1.0, 0.1, 0.01])
@pytest.mark.parametrize("name", BACKENDS)
def test_shallow_angle_to_a_plane(name, degrees):
    plate = hard_shape("hard/thin_plate", thickness=0.05)
    cast = ray_backends(plate.mesh)[name]
    rng = np.random.default_rng(4)
    a = np.radians(degrees)
    n_rays, t_exact = 2000, 0.05
    d = np.tile([np.cos(a), 0.0, -np.sin(a)], (n_rays, 1))
    top = 0.025
    o = np.c_[rng.uniform(-0.4, 0.4, (n_rays, 2)), np.full(n_rays, top + t_exact * np.sin(a))]
    t, hit, n = cast(o, d)
    assert_well_formed(t, hit, n)
    assert hit.all()
    assert np.abs(t - t_exact).max() / t_exact < 1e-3
    assert np.allclose(n, [0, 0, 1], atol=1e-6)
