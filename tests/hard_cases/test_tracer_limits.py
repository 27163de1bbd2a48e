"""Case 8: sphere tracing at grazing angles and near misses; step caps and over-relaxation.

Promise (ddfbench.evaluate.trace.sphere_trace, and every SDF family through it):
- a ray that passes a surface at a distance above the hit tolerance is never a hit: it misses, or
  runs out of steps and is UNDECIDED (t = inf, hit = False);
- UNDECIDED rays are counted: Hits.stats["undecided"] and the counting layer's undecided_rays equal
  the number of rays whose status is UNDECIDED;
- over-relaxation (omega > 1) never passes through a surface that plain tracing (omega = 1) finds:
  where plain tracing hits at t, the relaxed tracer hits at the same t, on exact distance fields and
  on trilinear grid fields, at grazing angles down to 0.1 degrees.
"""

import numpy as np
import pytest
import torch

from ddfbench.core.representation import Budget, FitData, RayStatus
from ddfbench.evaluate.trace import TraceOptions, sphere_trace
from ddfbench.models import load_family
from ddfbench.render.counting import CountedTracer
from ddfbench.truth.oracle import Oracle
from tests.hard_cases.conftest import hard_shape, unit
from tests.hard_cases.test_surface_start_rays import plate_sdf

R = 0.5


def sphere_sdf(p: torch.Tensor) -> torch.Tensor:
    return p.norm(dim=1) - R


def passing_rays(n, miss_by, seed):
    """Rays (origins at distance 1 before their closest approach, unit directions) passing the sphere of
    radius R at distance miss_by from its surface."""
    rng = np.random.default_rng(seed)
    d = unit(rng.normal(size=(n, 3)))
    perp = unit(np.cross(d, rng.normal(size=(n, 3))))
    return (R + miss_by) * perp - d, d


@pytest.mark.parametrize("max_steps", [16, 64, 256])
@pytest.mark.parametrize("miss_by", [1e-2, 1e-3, 1e-4])
def test_near_misses_are_never_hits(max_steps, miss_by):
    o, d = passing_rays(2000, miss_by, seed=int(1e5 * miss_by) + max_steps)
    res = sphere_trace(sphere_sdf, o, d, 0.6, TraceOptions(max_steps=max_steps))
    assert not res.hit.any() and np.all(np.isinf(res.t))
    assert set(np.unique(res.status).tolist()) <= {RayStatus.MISS, RayStatus.UNDECIDED}


def test_step_cap_is_undecided_and_counted():
    """A grid_sdf sphere traced with an 8-step cap: grazing rays stop UNDECIDED, counted by Hits.stats and
    the counting layer; none of them is a hit, and the clear hits still are."""
    shape = hard_shape("hard/dirty_sphere", zero_area=0, duplicate=0, flipped=0, unreferenced=0)
    rep = load_family("grid_sdf")({"resolution": 32, "build": "exact", "trace": {"max_steps": 8}})
    rep.fit(FitData(None, shape.mesh, Oracle(shape.mesh)), Budget())
    o1, d1 = passing_rays(500, 1e-3, seed=1)  # grazing near misses
    o2, d2 = passing_rays(500, -0.3, seed=2)  # clear hits
    o, d = np.r_[o1, o2], np.r_[d1, d2]
    raw = rep.intersect(o, d)
    undecided = raw.status == RayStatus.UNDECIDED
    assert undecided[:500].sum() > 50, "an 8-step cap should leave grazing rays undecided"
    assert raw.stats["undecided"] == int(undecided.sum())
    assert not raw.hit[undecided].any() and np.all(np.isinf(raw.t[undecided]))
    assert raw.hit[500:].all()
    tracer = CountedTracer(rep)
    cleaned = tracer.cast("primary", o, d, normals=True)
    assert tracer.counts["undecided_rays"] == int(undecided.sum())
    assert np.array_equal(cleaned.status, raw.status) and not cleaned.hit[undecided].any()


def grazing_plate_rays(n, seed):
    """Rays along +x at 0.1-5 degrees to the plates of a plate pair, starting around their face heights."""
    rng = np.random.default_rng(seed)
    a = np.radians(rng.choice([0.1, 0.5, 1.0, 5.0], n)) * rng.choice([-1, 1], n)
    d = np.c_[np.cos(a), np.zeros(n), np.sin(a)]
    z = rng.choice([-0.045, -0.025, 0.025, 0.045], n) + rng.normal(0, 0.01, n)
    o = np.c_[np.full(n, -0.7), rng.uniform(-0.4, 0.4, n), z]
    return o, d


def compare_relaxed(field, o, d, omega):
    plain = sphere_trace(field, o, d, 0.6, TraceOptions(max_steps=2000))
    relaxed = sphere_trace(field, o, d, 0.6, TraceOptions(max_steps=2000, omega=omega))
    found = plain.hit
    assert found.sum() > len(o) // 10
    lost = found & ~relaxed.hit
    assert not lost.any(), f"omega {omega}: {int(lost.sum())} of {int(found.sum())} surfaces that plain tracing finds were passed"
    assert np.abs(relaxed.t[found] - plain.t[found]).max() < 1e-4


@pytest.mark.parametrize("omega", [1.2, 1.6, 1.9])
def test_over_relaxation_keeps_grazing_hits_on_an_exact_field(omega):
    o, d = grazing_plate_rays(1500, seed=3)
    compare_relaxed(plate_sdf(0.05, 0.02), o, d, omega)


@pytest.fixture(scope="module")
def plate_grid():
    pair = hard_shape("hard/plate_pair", gap=0.05, thickness=0.02)
    rep = load_family("grid_sdf")({"resolution": 64, "build": "levelset"})
    rep.fit(FitData(None, pair.mesh, Oracle(pair.mesh)), Budget())
    return rep


@pytest.mark.parametrize("omega", [1.2, 1.6, 1.9])
def test_over_relaxation_keeps_grazing_hits_on_a_grid_field(plate_grid, omega):
    o, d = grazing_plate_rays(1500, seed=4)
    compare_relaxed(plate_grid.field, o, d, omega)


def test_field_jumping_to_minus_inf_gives_a_finite_hit():
    """A field that is finite before its surface and -inf past it (a diverged network's overflow) brackets a
    root with fb = -inf: regula falsi is inf/inf there, and the hit must still have a finite t (both tracers)."""
    from ddfbench.evaluate.trace_device import DeviceSphereTracer

    def field(p):
        return torch.where(p[:, 0] < 0.1, 0.4 - p[:, 0], torch.tensor(-float("inf")))

    o = np.array([[-0.5, 0.0, 0.0], [-0.5, 0.01, 0.0]], np.float32)
    d = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]], np.float32)
    res = sphere_trace(field, o, d, 0.6, TraceOptions())
    assert res.hit.all() and np.isfinite(res.t).all(), res.t
    assert np.allclose(res.t, 0.6, atol=1e-5)
    t = DeviceSphereTracer(field, 0.6, TraceOptions())(torch.from_numpy(o), torch.from_numpy(d))
    assert torch.isfinite(t).all() and torch.allclose(t, torch.full_like(t, 0.6), atol=1e-5), t
