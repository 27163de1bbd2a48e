"""Case 15: a one-triangle mesh and a million-triangle mesh run through shape, oracle, metrics and mesh family.

Promise: both load, answer rays and distances exactly, give finite metrics and fit / intersect /
save / load with the mesh family; the million-triangle torus (built with numpy in < 1 s) stays far
inside a 24 GB machine (peak resident memory of the whole test process below 8 GB).
"""

import resource

import numpy as np
import pytest

from ddfbench.core.representation import Budget, FitData
from ddfbench.evaluate.metrics import geometry_metrics
from ddfbench.models.mesh import MeshFamily
from ddfbench.truth.oracle import Oracle
from tests.hard_cases.conftest import assert_well_formed, hard_shape, has_warp, unit


def mesh_family_round_trip(mesh, o, d, tmp_path, save=True, backend="open3d"):
    rep = MeshFamily({"faces": 0, "backend": backend})
    rep.fit(FitData(samples=None, mesh=mesh, oracle=None), Budget())
    hits = rep.intersect(o, d)
    assert_well_formed(hits.t, hits.hit, hits.normal)
    if not save:
        return hits
    rep.save(str(tmp_path / "model"))
    again = MeshFamily.load(rep._saved_path)
    assert rep.storage_bytes() > 0 and len(again.to_mesh(0).faces) == len(mesh.faces)
    again_t = again.intersect(o, d).t
    assert np.array_equal(np.isinf(again_t), ~hits.hit) and np.allclose(again_t[hits.hit], hits.t[hits.hit], atol=1e-6)
    return hits


def test_one_triangle(tmp_path):
    shape = hard_shape("hard/one_triangle")
    assert len(shape.mesh.faces) == 1 and not shape.watertight
    o = np.array([[-0.3, -0.3, 1.0], [0.4, 0.4, 1.0], [-0.3, -0.3, -1.0]])  # over the triangle, beside it, below it
    d = np.array([[0, 0, -1.0], [0, 0, -1.0], [0, 0, 1.0]])
    hits = mesh_family_round_trip(shape.mesh, o, d, tmp_path)
    assert hits.hit.tolist() == [True, False, True] and np.allclose(hits.t[[0, 2]], 1.0)
    # a lone triangle encloses nothing: its winding number is below 1/2 everywhere. A vote of k independent
    # random rays still calls a point inside with probability P(Binomial(k, w) > k/2), w the triangle's
    # solid-angle share (up to 1/2 right next to it), so only points in its near field can be called inside,
    # and fewer with more rays. (open3d's own compute_occupancy called 8 % inside, some 0.5 away.)
    p = np.random.default_rng(0).uniform(-0.6, 0.6, (2000, 3))
    share = {k: Oracle(shape.mesh, occupancy_rays=k).occupancy(p).mean() for k in (5, 31)}
    assert share[5] < 0.05 and share[31] < share[5]
    orc = Oracle(shape.mesh)
    assert np.isfinite(orc.signed_distance(p)).all()
    m = geometry_metrics(shape.mesh, shape.mesh, 20000, [0.01], seed=0)  # spacing ~0.005 on the 0.5-area face
    assert m["empty_reconstruction"] is False and m["chamfer_l2"] < 1e-3 and m["fscore"]["0.01"] > 0.9


@pytest.mark.slow
def test_million_triangles(tmp_path):
    shape = hard_shape("hard/torus_grid", segments=1000)
    assert len(shape.mesh.faces) == 1_000_000 and shape.watertight and shape.warnings == []
    rng = np.random.default_rng(1)
    o = rng.uniform(-0.6, 0.6, (50000, 3))
    d = unit(rng.normal(size=(50000, 3)))
    hits = mesh_family_round_trip(shape.mesh, o, d, tmp_path, save=False)
    t_embree, tri, _ = Oracle(shape.mesh, "embree").first_hit(o, d)
    for hits in [hits] + ([mesh_family_round_trip(shape.mesh, o, d, tmp_path, False, "warp")] if has_warp() else []):
        both = hits.hit & (tri >= 0)
        assert (hits.hit != (tri >= 0)).mean() < 1e-3 and np.abs(hits.t[both] - t_embree[both]).max() < 1e-4
    # analytic torus (major 0.35, minor 0.15 before normalization; normalized scale 1/1.0)
    p = rng.uniform(-0.6, 0.6, (20000, 3))
    s = shape.transform["scale"]
    q = p / s
    exact = np.hypot(np.hypot(q[:, 0], q[:, 1]) - 0.35, q[:, 2]) - 0.15
    assert np.abs(Oracle(shape.mesh).signed_distance(p) / s - exact).max() < 1e-4
    m = geometry_metrics(shape.mesh, shape.mesh, 20000, [0.01], seed=0)
    assert m["chamfer_l2"] < 1e-4
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    assert peak_gb < 8, f"peak resident memory {peak_gb:.1f} GB"
