"""Case 1: rays aimed exactly at the vertices and edge midpoints of a cube.

Promise: every ray-cast backend (oracle open3d, embree and warp, the mesh family on each)
reports a hit at the exact entry distance, and `Oracle.count_crossings` counts each
surface crossing once (2 for a ray that enters and leaves the cube), even where the
ray passes through a vertex or an edge shared by several triangles.
"""

import numpy as np
import pytest

from ddfbench.core.representation import Budget, FitData, RayStatus
from ddfbench.models.mesh import MeshFamily
from ddfbench.truth.oracle import Oracle
from tests.hard_cases.conftest import backend_params, unit


def entering_rays(cube_mesh, rng, per_target=4):
    """Rays through every vertex and edge midpoint (cube edges and face diagonals) that enter the cube there.

    Returns origins (N,3), unit directions (N,3) and the analytic entry and exit distances (N,), (N,).
    """
    v = np.asarray(cube_mesh.vertices)
    targets = np.vstack([v, v[cube_mesh.edges_unique].mean(axis=1)])
    targets = np.repeat(targets, per_target, axis=0)
    on_face = np.isclose(np.abs(targets), 0.5)  # which face planes each target lies on
    u = rng.uniform(0.2, 1.0, targets.shape) * np.where(on_face, np.sign(targets), rng.choice([-1, 1], targets.shape))
    u[::per_target] = np.where(on_face, np.sign(targets), 0.0)[::per_target]  # one straight-in ray per target
    d = unit(-u)
    o = targets - 0.7 * d
    # slab method in float64: entry and exit of the ray through [-0.5, 0.5]^3
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (-0.5 - o) / d, (0.5 - o) / d
    lo = np.where(d == 0, -np.inf, np.minimum(t1, t2)).max(axis=1)
    hi = np.where(d == 0, np.inf, np.maximum(t1, t2)).min(axis=1)
    return o, d, lo, hi


@pytest.fixture(scope="module")
def rays(cube):
    return entering_rays(cube.mesh, np.random.default_rng(7))


def test_rays_really_enter_at_the_target(rays):
    o, d, t_in, t_out = rays
    assert np.allclose(t_in, 0.7) and np.all(t_out > t_in + 1e-3)


@pytest.mark.parametrize("backend", backend_params("open3d", "embree", "warp"))
def test_oracle_hits_at_the_entry(cube, rays, backend):
    o, d, t_in, _ = rays
    t, tri, n = Oracle(cube.mesh, backend).first_hit(o, d)
    assert np.all(tri >= 0), f"{backend}: {int((tri < 0).sum())} of {len(tri)} rays through vertices/edges missed"
    assert np.abs(t - t_in).max() < 1e-5
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)
    assert np.all(np.einsum("ij,ij->i", n, d) < 0)


@pytest.mark.parametrize("backend", backend_params("open3d", "embree", "warp"))
def test_mesh_family_hits_at_the_entry(cube, rays, backend):
    o, d, t_in, _ = rays
    rep = MeshFamily({"faces": 0, "backend": backend})
    rep.fit(FitData(samples=None, mesh=cube.mesh, oracle=None), Budget())
    hits = rep.intersect(o, d)
    assert hits.hit.all() and np.all(hits.status == RayStatus.HIT)
    assert np.abs(hits.t - t_in).max() < 1e-5
    assert np.isfinite(hits.normal).all()


def test_exit_is_hit_from_inside(cube, rays):
    """The second crossing: from just inside the entry, the first hit is the analytic exit."""
    o, d, t_in, t_out = rays
    t, tri, _ = Oracle(cube.mesh).first_hit(o + (t_in + 1e-3)[:, None] * d, d)
    assert np.all(tri >= 0)
    assert np.abs(t - (t_out - t_in - 1e-3)).max() < 1e-5


def test_count_crossings_counts_each_crossing_once(cube, rays):
    """Oracle.count_crossings counts a ray through a vertex or an edge of the cube as 2 crossings, like
    any other ray through it (a count per touched triangle would give 3-6), so parity-based callers
    (odd-even sample rejection) are right on such rays."""
    o, d, _, _ = rays
    counts = Oracle(cube.mesh).count_crossings(o, d)
    wrong = counts != 2
    assert not wrong.any(), (f"{int(wrong.sum())} of {len(counts)} rays through vertices/edges counted "
                             f"{sorted(set(counts[wrong].tolist()))} crossings instead of 2")
