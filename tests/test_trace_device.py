"""DeviceSphereTracer (ddfbench/evaluate/trace_device.py) against sphere_trace and closed-form answers.

References: ray-sphere intersection in closed form, sphere_trace on the same rays and options, a box SDF,
a grid SDF built exactly on the catalog sphere and a small neural SDF fitted a few steps.
"""

import math
import os

import numpy as np
import pytest
import torch

from ddfbench.bench.views import incoherent_rays, view_rays
from ddfbench.core.errors import InputError
from ddfbench.core.representation import Budget, FitData
from ddfbench.evaluate.trace import TraceOptions, sphere_trace
from ddfbench.evaluate.trace_device import DeviceSphereTracer
from tests.test_trace import CountingField, analytic_hit

R = 0.5
DOMAIN = 0.6
OPT = TraceOptions()  # every preset's trace block: eps 1e-5, eps_abs 1e-6, 256 steps, omega 1, 24 refinements


def sphere(p: torch.Tensor) -> torch.Tensor:
    return p.norm(dim=1) - R


def box(p: torch.Tensor, half=(0.3, 0.2, 0.4)) -> torch.Tensor:
    q = p.abs() - torch.tensor(half, dtype=p.dtype)
    return q.clamp_min(0).norm(dim=1) + q.amax(dim=1).clamp_max(0)


def analytic(o: np.ndarray, d: np.ndarray):
    """tests.test_trace.analytic_hit for this file's sphere (radius R): the first crossing t, inf on a miss."""
    return analytic_hit(o, d, radius=R)


def trace(field, o, d, **kw):
    opts = kw.pop("options", OPT)
    tracer = DeviceSphereTracer(field, DOMAIN, opts, **kw)
    t = tracer(torch.as_tensor(o), torch.as_tensor(d))
    assert t.dtype == torch.float32 and t.shape == (len(o),)
    return t.numpy(), tracer


def rays():
    """A 40^2 pinhole view and 3000 incoherent rays (origins inside the box), float32 numpy."""
    (o1, d1), (o2, d2) = view_rays(40), incoherent_rays(3000, seed=0)
    return np.concatenate([o1, o2]), np.concatenate([d1, d2])


def compare(field, o, d, options=OPT, **kw):
    """-> (mask agreement, depth MAE on rays both hit, both-hit count) of the device tracer against sphere_trace,
    leaving out rays whose first point lies within start_offset of the surface (sphere_trace escapes them first;
    the device tracer does not, by design)."""
    t, _ = trace(field, o, d, options=options, **kw)
    ref = sphere_trace(field, o, d, DOMAIN, options)
    with torch.no_grad():
        f0 = field(torch.as_tensor(o)).float().numpy()  # an origin outside the box is farther than that anyway
    plain = np.abs(f0) >= options.start_offset
    hit = np.isfinite(t)
    both = plain & hit & ref.hit
    return float((hit == ref.hit)[plain].mean()), float(np.abs(t[both] - ref.t[both]).mean()), int(both.sum())


# ---- agreement with sphere_trace and with the analytic sphere ---------------------------------------------------
def test_sphere_matches_sphere_trace_and_the_closed_form():
    o, d = rays()
    agree, mae, n_both = compare(sphere, o, d)
    assert agree >= 0.995 and n_both > 1500
    assert mae <= 1e-5
    t, tracer = trace(sphere, o, d)
    ref, disc = analytic(o, d)
    inside = np.linalg.norm(o, axis=1) < R
    assert inside.sum() > 300  # incoherent rays inside the sphere: they trace to the exit
    clear = np.isfinite(ref) & (disc > 0.02) & (np.abs(np.linalg.norm(o, axis=1) - R) > OPT.start_offset)
    assert np.isfinite(t[clear]).all()
    assert np.abs(t[clear] - ref[clear]).max() < 4e-5  # tolerance / cos(incidence)
    assert np.isinf(t[np.isinf(ref)]).all()
    # the hit points lie on the ray's side of the surface, within the hit tolerance
    h = np.isfinite(t)
    gap = (np.linalg.norm(o[h] + t[h, None] * d[h], axis=1) - R) * np.where(inside[h], -1, 1)
    assert gap.min() > -1e-6 and gap.max() < OPT.eps * t[h].max() + 2 * OPT.eps_abs
    assert 0 < tracer.trace_steps == tracer.field_evals  # a 1-Lipschitz field: no sign change, no refinement


def test_box_sdf_matches_sphere_trace():
    o, d = view_rays(40)
    agree, mae, n_both = compare(box, o, d)
    assert agree >= 0.995 and n_both > 300 and mae <= 1e-5


def test_a_ray_starting_inside_finds_the_exit():
    rng = np.random.default_rng(7)
    d = rng.normal(size=(200, 3))
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    o = (rng.uniform(-0.2, 0.2, (200, 3))).astype(np.float32)
    t, _ = trace(sphere, o, d)
    ref, _ = analytic(o, d)
    assert np.isfinite(ref).all()
    assert np.abs(t - ref).max() < 2e-5
    t0, _ = trace(sphere, np.zeros((1, 3), np.float32), np.array([[0.0, 0.6, 0.8]], np.float32))
    assert abs(t0[0] - R) < 1e-5


def test_sign_change_field_is_refined_to_the_surface():
    field = CountingField(lambda p: 3.0 * sphere(p))  # not 1-Lipschitz: steps overshoot, hits come from brackets
    o, d = view_rays(32)
    t, tracer = trace(field, o, d)
    ref, disc = analytic(o, d)
    assert tracer.field_evals > tracer.trace_steps  # refinement evaluations happened
    assert tracer.field_evals == sum(field.batches)
    # a step of 3x the distance can also jump a whole chord (a miss sphere_trace makes too); what is a hit lies on
    # the sphere, at the first crossing
    hit = np.isfinite(t)
    assert hit.sum() > 0.6 * np.isfinite(ref).sum() > 300
    assert np.isfinite(ref[hit]).all()
    radius = np.linalg.norm(o[hit] + t[hit, None] * d[hit], axis=1)
    assert np.abs(radius - R).max() < 1e-5
    clear = hit & (disc > 0.01)
    assert np.abs(t[clear] - ref[clear]).max() < 1e-4
    agree, mae, _ = compare(lambda p: 3.0 * sphere(p), o, d)
    assert agree >= 0.995 and mae < 1e-5


# ---- work and host round trips ---------------------------------------------------------------------------------
def test_rays_missing_the_box_cost_no_evaluation():
    n_hit, n_out = 64, 300
    o_out = np.tile(np.float32([[2.0, 2.0, 2.0]]), (n_out, 1))
    d_out = np.tile(np.float32([[1.0, 0.0, 0.0]]), (n_out, 1))  # pointing away: never meets the box
    o_hit, d_hit = view_rays(8)
    field = CountingField(sphere)
    t, tracer = trace(field, o_out, d_out)
    assert field.batches == [] and tracer.field_evals == 0 and np.isinf(t).all()
    o, d = np.concatenate([o_out, o_hit]), np.concatenate([d_out, d_hit])
    t, tracer = trace(field, o, d)
    assert max(field.batches) <= n_hit and tracer.field_evals == sum(field.batches)
    assert np.isinf(t[:n_out]).all() and np.isfinite(t[n_out:]).any()


def test_a_field_that_never_converges_leaves_rays_undecided():
    field = CountingField(lambda p: torch.full((p.shape[0],), 1e-3))  # 1e-3 a step: 40 steps never leave the box
    o, d = view_rays(8)
    opts = TraceOptions(max_steps=40)
    t, tracer = trace(field, o, d, options=opts, sync_every=8)
    assert np.isinf(t).all()
    assert tracer.field_evals == 40 * len(o) == sum(field.batches)  # every ray every step: none stopped
    # box clip + compactions after steps 8, 16, 24, 32 (none after the last chunk) + the bracket gather
    assert tracer.host_syncs == 1 + 4 + 1
    ref = sphere_trace(field, o, d, DOMAIN, opts)
    assert not ref.hit.any() and (ref.status == 2).all()


@pytest.mark.parametrize("sync_every", [1, 8, 32])
def test_host_syncs_are_bounded_by_max_steps_over_sync_every(sync_every):
    o, d = view_rays(32)
    opts = TraceOptions(max_steps=64)
    t, tracer = trace(sphere, o, d, options=opts, sync_every=sync_every)
    ref = sphere_trace(sphere, o, d, DOMAIN, opts)
    assert np.array_equal(np.isfinite(t), ref.hit)
    assert tracer.host_syncs <= math.ceil(64 / sync_every) + 2
    if sync_every > 1:
        assert ref.host_syncs > 2 * tracer.host_syncs
    # frozen rays are evaluated until the next compaction: at most sync_every - 1 extra evaluations per ray
    assert ref.trace_steps <= tracer.trace_steps <= ref.trace_steps + (sync_every - 1) * len(o)


# ---- options and precision -------------------------------------------------------------------------------------
def test_unsupported_options_are_input_errors():
    with pytest.raises(InputError, match="omega"):
        DeviceSphereTracer(sphere, DOMAIN, TraceOptions(omega=1.6))
    with pytest.raises(InputError, match="precision"):
        DeviceSphereTracer(sphere, DOMAIN, OPT, precision="fp16")
    with pytest.raises(InputError, match="sync_every"):
        DeviceSphereTracer(sphere, DOMAIN, OPT, sync_every=0)
    with pytest.raises(InputError, match="float32"):
        DeviceSphereTracer(sphere, DOMAIN, OPT)(torch.zeros(2, 3, dtype=torch.float64), torch.zeros(2, 3))


def test_tf32_is_off_in_fp32_and_the_flags_are_restored():
    seen = []

    def field(p):
        seen.append(torch.backends.cuda.matmul.allow_tf32)
        return sphere(p)

    saved = torch.backends.cuda.matmul.allow_tf32
    try:
        torch.backends.cuda.matmul.allow_tf32 = True
        trace(field, *view_rays(4))
        assert seen and not any(seen)
        assert torch.backends.cuda.matmul.allow_tf32 is True
    finally:
        torch.backends.cuda.matmul.allow_tf32 = saved


# ---- learned fields --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sphere_shape():
    from ddfbench.truth.oracle import Oracle
    from ddfbench.truth.shapes import load_shape

    shape = load_shape({"name": "sphere"})  # the catalog icosphere, radius 0.5
    return shape.mesh, Oracle(shape.mesh)


@pytest.fixture(scope="module")
def neural(sphere_shape):
    from ddfbench.models import load_family
    from ddfbench.sampling.oracle_sdf import oracle_sdf_samples

    mesh, oracle = sphere_shape
    rep = load_family("neural_sdf")({"width": 32, "depth": 3, "n_harmonics": 2, "batch": 1024, "lr": 3e-3}, DOMAIN)
    rep.fit(FitData(oracle_sdf_samples(mesh, oracle, 5000, seed=0), mesh, oracle),
            Budget(max_steps=60, max_seconds=20, n_probes=0))
    return rep


def test_grid_sdf_matches_sphere_trace(sphere_shape):
    from ddfbench.models import load_family

    mesh, oracle = sphere_shape
    rep = load_family("grid_sdf")({"resolution": 24, "build": "exact"}, DOMAIN)
    rep.fit(FitData(None, mesh, oracle), Budget(n_probes=0))
    o, d = view_rays(32)
    agree, mae, n_both = compare(rep.field, o, d, rep.trace_options)
    assert agree >= 0.995 and n_both > 200 and mae <= 1e-5


def test_neural_sdf_matches_sphere_trace(neural):
    o, d = view_rays(24)
    agree, mae, n_both = compare(neural.field, o, d, neural.trace_options)
    assert agree >= 0.995 and n_both > 100 and mae <= 1e-5


def test_bf16_agrees_with_fp32_at_the_bf16_tolerance(neural):
    o, d = view_rays(24)
    loose = TraceOptions(eps_abs=1e-3)  # the named bf16 deviation, in fp32 for the reference
    t, tracer = trace(neural.field, o, d, precision="bf16")
    assert tracer.eps_abs == 1e-3
    ref = sphere_trace(neural.field, o, d, DOMAIN, loose)
    hit = np.isfinite(t)
    assert ref.hit.sum() > 100
    assert (hit == ref.hit).mean() >= 0.98
    both = hit & ref.hit
    assert np.median(np.abs(t[both] - ref.t[both])) < 1e-2


@pytest.mark.slow  # torch.compile on the CPU: about 30 s cold, 6 s with inductor's cache warm
def test_compiled_step_matches_eager():
    o, d = view_rays(16)
    eager, _ = trace(sphere, o, d)
    t, tracer = trace(sphere, o, d, compiled=True)
    assert np.array_equal(np.isfinite(t), np.isfinite(eager))
    h = np.isfinite(t)
    assert np.abs(t[h] - eager[h]).max() < 1e-5 and tracer.host_syncs <= math.ceil(OPT.max_steps / 8) + 2


# ---- on a GPU --------------------------------------------------------------------------------------------------
GPU = os.environ.get("DDFBENCH_GPU_TEST_DEVICE", "cuda")  # cpu: a dry run of the test below without a GPU


@pytest.mark.gpu
@pytest.mark.skipif(GPU.startswith("cuda") and not torch.cuda.is_available(),
                    reason="no CUDA device: pytest -m gpu needs an NVIDIA GPU")
def test_on_the_device_matches_sphere_trace_without_leaving_it():
    torch.manual_seed(0)
    mlp = torch.nn.Sequential(torch.nn.Linear(3, 64), torch.nn.Softplus(100), torch.nn.Linear(64, 1)).to(GPU)
    with torch.no_grad():
        mlp[2].weight.mul_(0.05)  # a gentle bump on the sphere: slope well below 1

    def neural_field(p):
        return sphere(p) + mlp(p).reshape(-1)

    o, d = view_rays(64)
    og, dg = torch.as_tensor(o, device=GPU), torch.as_tensor(d, device=GPU)
    loose = TraceOptions(eps_abs=1e-4)  # TF32 products carry about 1e-4 of error into the field
    for field, precision, opts, (agree, mae) in ((sphere, "fp32", OPT, (0.995, 1e-5)),
                                                 (neural_field, "fp32", OPT, (0.995, 1e-5)),
                                                 (neural_field, "tf32", loose, (0.98, 1e-3))):
        tracer = DeviceSphereTracer(field, DOMAIN, opts, precision=precision)
        t = tracer(og, dg)
        assert t.device == og.device
        ref = sphere_trace(field, o, d, DOMAIN, opts, GPU)
        hit = torch.isfinite(t).cpu().numpy()
        assert (hit == ref.hit).mean() >= agree and ref.hit.sum() > 1000
        both = hit & ref.hit
        assert np.abs(t.cpu().numpy()[both] - ref.t[both]).mean() <= mae
        assert tracer.host_syncs <= math.ceil(opts.max_steps / 8) + 2 < ref.host_syncs
