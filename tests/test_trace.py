"""Sphere tracer: analytic spheres as the reference (ray-sphere intersection in closed form)."""

import numpy as np
import pytest
import torch

from ddfbench.core import plugins
from ddfbench.core.errors import InputError
from ddfbench.core.representation import RayStatus
from ddfbench.evaluate.trace import (
    TraceOptions,
    autograd_normals,
    central_difference_normals,
    numpy_field,
    sphere_trace,
    to_hits,
)

R = 0.4
DOMAIN = 0.6


def sphere(p: torch.Tensor) -> torch.Tensor:
    return p.norm(dim=1) - R


def analytic_hit(o: np.ndarray, d: np.ndarray, center=(0.0, 0.0, 0.0), radius: float = R):
    """First intersection t (inf on a miss) and the discriminant (how far from grazing) of rays with a sphere."""
    oc = o.astype(np.float64) - np.asarray(center)
    b = (oc * d).sum(1)
    disc = b * b - ((oc * oc).sum(1) - radius**2)
    root = np.sqrt(np.maximum(disc, 0))
    t_near, t_far = -b - root, -b + root
    t = np.where(t_near >= 0, t_near, t_far)
    return np.where((disc > 0) & (t_far >= 0), t, np.inf), disc


def random_rays(n: int, seed: int, dist: float = 1.5):
    rng = np.random.default_rng(seed)
    o = rng.normal(size=(n, 3))
    o = o / np.linalg.norm(o, axis=1, keepdims=True) * dist
    d = rng.uniform(-0.5, 0.5, (n, 3)) - o
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return o.astype(np.float32), d.astype(np.float32)


class CountingField:
    """Wraps a field, recording every batch size it is called with."""

    def __init__(self, fn):
        self.fn, self.batches = fn, []

    def __call__(self, p):
        self.batches.append(int(p.shape[0]))
        return self.fn(p)


def test_hits_match_analytic_sphere():
    o, d = random_rays(4000, 0)
    ref, disc = analytic_hit(o, d)
    res = sphere_trace(sphere, o, d, DOMAIN)
    assert np.array_equal(res.hit, np.isfinite(ref))
    # every hit point lies within the hit tolerance eps*t + eps_abs of the surface, on the ray's side
    p = o[res.hit] + res.t[res.hit, None] * d[res.hit]
    gap = np.linalg.norm(p.astype(np.float64), axis=1) - R
    assert np.all(gap > -1e-6) and np.all(gap < 1e-5 * res.t[res.hit] + 1e-6 + 1e-6)
    # along the ray that is t error <= tolerance / cos(incidence); cos >= 0.35 where disc > 0.02
    clear = res.hit & (disc > 0.02)
    assert clear.sum() > 1000
    assert np.abs(res.t[clear] - ref[clear]).max() < 4e-5
    assert np.all(np.isinf(res.t[~res.hit]))
    assert set(np.unique(res.status[res.hit])) == {RayStatus.HIT}


def test_refinement_on_sign_change_matches_analytic():
    # twice the SDF: steps overshoot, so hits come from bracketed sign changes and refinement
    o, d = random_rays(3000, 1)
    ref, disc = analytic_hit(o, d)
    field = CountingField(lambda p: 2.0 * sphere(p))
    res = sphere_trace(field, o, d, DOMAIN)
    clear = res.hit & (disc > 1e-2)
    assert res.field_evals > res.trace_steps  # refinement evaluations happened
    assert np.abs(res.t[clear] - ref[clear]).max() < 1e-4
    assert np.median(np.abs(res.t[clear] - ref[clear])) < 1e-6


def test_step_cap_is_undecided_not_hit():
    o, d = random_rays(500, 2)
    ref, _ = analytic_hit(o, d)
    res = sphere_trace(sphere, o, d, DOMAIN, TraceOptions(max_steps=2))
    undecided = res.status == RayStatus.UNDECIDED
    assert undecided.sum() > 100
    assert not res.hit[undecided].any() and np.all(np.isinf(res.t[undecided]))
    # what the capped run does call a hit is a true hit
    assert np.all(np.isfinite(ref[res.hit]))
    hits = to_hits(res, d)
    assert hits.stats["undecided"] == int(undecided.sum())


def test_only_active_rays_are_evaluated():
    rng = np.random.default_rng(3)
    n_head, n_out, n_slow = 200, 300, 100
    # head-on rays toward the center: one step reaches the surface exactly -> 2 evaluations each
    o_head = rng.normal(size=(n_head, 3))
    o_head = o_head / np.linalg.norm(o_head, axis=1, keepdims=True) * 0.55
    d_head = -o_head / np.linalg.norm(o_head, axis=1, keepdims=True)
    # rays that miss the domain box entirely -> no evaluation
    o_out = np.tile([[2.0, 2.0, 2.0]], (n_out, 1)) + rng.normal(size=(n_out, 3)) * 0.1
    d_out = np.tile([[1.0, 0.0, 0.0]], (n_out, 1))
    # nearly grazing rays: many steps
    o_slow, d_slow = random_rays(n_slow, 4)
    o = np.concatenate([o_head, o_out, o_slow]).astype(np.float32)
    d = np.concatenate([d_head, d_out, d_slow]).astype(np.float32)

    head = CountingField(sphere)
    res = sphere_trace(head, o[:n_head + n_out], d[:n_head + n_out], DOMAIN)
    assert res.field_evals == sum(head.batches) == 2 * n_head
    assert res.hit[:n_head].all() and not res.hit[n_head:].any()

    # all together: the total equals the sum of each ray traced alone, far below rays x iterations
    together = CountingField(sphere)
    res = sphere_trace(together, o, d, DOMAIN)
    alone = 0
    for i in range(len(o)):
        one = sphere_trace(sphere, o[i:i + 1], d[i:i + 1], DOMAIN)
        alone += one.field_evals
        assert one.hit[0] == res.hit[i]
    assert res.field_evals == sum(together.batches) == alone
    # the host waits for the device a bounded number of times per loop step, whatever the ray count:
    # one compaction and one bracket check a step (one more on a step with crossings), two at the start
    steps = len(together.batches)
    assert 2 + 2 * steps <= res.host_syncs <= 2 + 3 * steps
    assert to_hits(res, d).stats["host_syncs"] == res.host_syncs
    assert res.field_evals < 0.5 * len(together.batches) * len(o)
    assert together.batches == sorted(together.batches, reverse=True)  # the active set only shrinks


def union_of_spheres(centers: np.ndarray, radii: np.ndarray):
    c, r = torch.from_numpy(centers.astype(np.float32)), torch.from_numpy(radii.astype(np.float32))
    return lambda p: ((p[:, None, :] - c[None]).norm(dim=2) - r[None]).amin(dim=1)


@pytest.mark.parametrize("omega", [1.3, 1.6, 1.9])
def test_over_relaxation_never_passes_a_surface_plain_tracing_finds(omega):
    rng = np.random.default_rng(5)
    centers = rng.uniform(-0.4, 0.4, (40, 3))
    radii = rng.uniform(0.005, 0.05, 40)  # small, thin targets are easy to step over
    field = union_of_spheres(centers, radii)
    o, d = random_rays(4000, 6, dist=1.0)
    plain = sphere_trace(field, o, d, DOMAIN, TraceOptions(omega=1.0))
    relaxed = sphere_trace(field, o, d, DOMAIN, TraceOptions(omega=omega))
    assert plain.hit.sum() > 200
    assert np.array_equal(relaxed.hit, plain.hit)
    assert np.abs(relaxed.t[plain.hit] - plain.t[plain.hit]).max() < 1e-4
    # independent reference: the nearest analytic sphere intersection
    ref = np.min([analytic_hit(o, d, c, r)[0] for c, r in zip(centers, radii)], axis=0)
    assert np.abs(relaxed.t[relaxed.hit] - ref[relaxed.hit]).max() < 1e-3
    assert relaxed.trace_steps != plain.trace_steps  # relaxation did change the march


def test_over_relaxation_saves_steps_along_a_plane():
    # rays nearly parallel to a plane: the case Keinert et al. accelerate
    plane = lambda p: p[:, 1] + 0.03  # noqa: E731
    n = 500
    o = np.tile([[-0.55, 0.0, 0.0]], (n, 1)).astype(np.float32)
    ang = np.linspace(0.035, 0.1, n)
    d = np.stack([np.cos(ang), -np.sin(ang), np.zeros(n)], 1).astype(np.float32)
    plain = sphere_trace(plane, o, d, DOMAIN, TraceOptions(omega=1.0))
    relaxed = sphere_trace(plane, o, d, DOMAIN, TraceOptions(omega=1.6))
    assert plain.hit.all() and relaxed.hit.all()
    assert np.abs(relaxed.t - 0.03 / np.sin(ang)).max() < 1e-3
    assert relaxed.trace_steps < 0.7 * plain.trace_steps


def test_under_relaxation_finds_the_same_hits_in_more_steps():
    o, d = random_rays(2000, 8)
    plain = sphere_trace(sphere, o, d, DOMAIN, TraceOptions(omega=1.0, max_steps=4000))
    under = sphere_trace(sphere, o, d, DOMAIN, TraceOptions(omega=0.7, max_steps=4000))  # room for grazing rays
    exact, disc = analytic_hit(o, d)
    assert plain.hit.sum() > 500 and np.array_equal(under.hit, plain.hit)
    clear = under.hit & (disc > 1e-3)  # off the silhouette, where |f| < tol pins t down
    assert clear.sum() > 400 and np.abs(under.t[clear] - exact[clear]).max() < 1e-3
    assert under.trace_steps > 1.5 * plain.trace_steps  # steps of 0.7 r, not r


def test_secondary_rays_do_not_self_hit():
    rng = np.random.default_rng(7)
    n = 2000
    normal = rng.normal(size=(n, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    p = (normal * R).astype(np.float32)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    cos = (d * normal).sum(1)
    res = sphere_trace(sphere, p, d.astype(np.float32), DOMAIN)
    leaving, entering = cos > 0.1, cos < -0.1
    assert not res.hit[leaving].any()  # a convex surface: a ray leaving it meets nothing
    assert (res.status[leaving] == RayStatus.MISS).all()
    # a ray entering finds the far side of the sphere (a chord of length 2 R |cos|)
    assert res.hit[entering].all()
    assert np.abs(res.t[entering] - 2 * R * np.abs(cos[entering])).max() < 1e-4
    # grazing rays may stay undecided but are never hits at their origin
    assert np.all(res.t[res.hit] > 1e-3)


def test_shadow_ray_hits_the_other_object():
    field = union_of_spheres(np.array([[-0.25, 0, 0], [0.25, 0, 0]]), np.array([0.15, 0.15]))
    o = np.array([[-0.1, 0.0, 0.0]], np.float32)  # on the first sphere, facing the second
    res = sphere_trace(field, o, np.array([[1.0, 0.0, 0.0]], np.float32), DOMAIN)
    assert res.hit[0] and abs(res.t[0] - 0.2) < 1e-5


def test_ray_from_inside_finds_the_exit():
    o = np.zeros((3, 3), np.float32)
    d = np.eye(3, dtype=np.float32)
    res = sphere_trace(sphere, o, d, DOMAIN)
    assert res.hit.all() and np.allclose(res.t, R, atol=1e-5)


def test_numpy_field_gives_the_same_answer():
    o, d = random_rays(300, 8)
    np_sphere = numpy_field(lambda p: np.linalg.norm(p, axis=1) - R)
    a = sphere_trace(sphere, o, d, DOMAIN)
    b = sphere_trace(np_sphere, o, d, DOMAIN)
    assert np.array_equal(a.hit, b.hit) and np.allclose(a.t[a.hit], b.t[b.hit], atol=1e-6)


def test_normals_face_the_ray_and_match_the_sphere():
    o, d = random_rays(500, 9)
    res = sphere_trace(sphere, o, d, DOMAIN)
    pts = torch.from_numpy(o[res.hit] + res.t[res.hit, None] * d[res.hit])
    exact = pts.numpy() / np.linalg.norm(pts.numpy(), axis=1, keepdims=True)
    for nrm, valid in (autograd_normals(sphere, pts), central_difference_normals(sphere, pts, 1e-3)):
        assert valid.all() and np.abs(nrm.numpy() - exact).max() < 1e-3
    hits = to_hits(res, d, autograd_normals(sphere, pts)[0].numpy(), np.ones(len(pts), bool), backward_passes=len(pts))
    assert (np.einsum("ij,ij->i", hits.normal[hits.hit], d[hits.hit]) < 0).all()
    # a ray leaving from inside sees the inner side: the normal is flipped toward it
    inside = sphere_trace(sphere, np.zeros((1, 3), np.float32), np.array([[0, 0, 1.0]], np.float32), DOMAIN)
    p_in = torch.tensor([[0.0, 0.0, R]])
    h_in = to_hits(inside, np.array([[0, 0, 1.0]], np.float32), autograd_normals(sphere, p_in)[0].numpy(), np.ones(1, bool))
    assert np.allclose(h_in.normal[0], [0, 0, -1], atol=1e-5)
    assert hits.stats["backward_passes"] == len(pts) and hits.stats["trace_steps"] == res.trace_steps


def test_bad_options_are_input_errors():
    o, d = random_rays(2, 0)
    with pytest.raises(InputError, match="omega"):
        sphere_trace(sphere, o, d, DOMAIN, TraceOptions(omega=2.5))
    declared = plugins.defaults("model", "neural_sdf")["trace"]
    with pytest.raises(InputError, match="unknown"):
        TraceOptions.from_cfg({"trace": {**declared, "omgea": 1.5}})
    with pytest.raises(InputError, match=r"^model\.trace\.omega: missing"):
        TraceOptions.from_cfg({"trace": {k: v for k, v in declared.items() if k != "omega"}})
    assert TraceOptions.from_cfg({"trace": {**declared, "omega": 1.5, "max_steps": 64}}).max_steps == 64
