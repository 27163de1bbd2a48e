"""`pytest -m gpu`: every family answers the same rays on CUDA as on the CPU, within tolerance, and no
image holds a NaN; every learned family trains end to end with train.device=cuda.

Skipped without CUDA (CI stays on the CPU). DDFBENCH_GPU_TEST_DEVICE=cpu runs the same checks with
the CPU standing in for the GPU (a dry run of this file on a machine without one).
Each family is fitted once on the CPU (the quick configs of the hard-case suite), answers a pinhole
view and incoherent rays there, is moved with Representation.to(device) and answers again.
"""

import glob
import os

import numpy as np
import pytest
import torch

from ddfbench.bench.views import incoherent_rays, view_rays
from ddfbench.truth.shapes import load_shape
from tests.hard_cases.conftest import ORACLE_BACKEND, compose, has_family, has_warp

DEVICE = os.environ.get("DDFBENCH_GPU_TEST_DEVICE", "cuda")
pytestmark = [
    pytest.mark.gpu,
    pytest.mark.skipif(DEVICE.startswith("cuda") and not torch.cuda.is_available(),
                       reason="no CUDA device: pytest -m gpu needs an NVIDIA GPU"),
]
# mesh: exact casts on both sides; sphere tracers: a silhouette ray may flip between hit and miss
# (float32 sums in another order); DDF: one network query per ray
TOLERANCE = {"mesh": (1.0, 1e-5), "grid_sdf": (0.995, 1e-4), "neural_sdf": (0.995, 1e-4), "gan_sdf": (0.99, 1e-4),
             "ddf": (0.995, 1e-4)}
FAMILIES = [f for f in TOLERANCE if has_family(f)]


@pytest.fixture(scope="module", autouse=True)
def float32_on_the_device():
    """CPU and device both in float32: TF32 off for matrix products and cuDNN convolutions."""
    from ddfbench.bench.timing import precision_context

    with precision_context("fp32", DEVICE):
        yield


def rays() -> tuple[np.ndarray, np.ndarray]:
    o1, d1 = view_rays(32)
    o2, d2 = incoherent_rays(1000, seed=3)
    return np.vstack([o1, o2]), np.vstack([d1, d2])


def assert_no_nan(hits, where: str) -> None:
    assert not np.isnan(hits.t).any(), f"{where}: NaN depth"
    assert np.isfinite(hits.normal).all(), f"{where}: non-finite normal"
    assert np.array_equal(hits.hit, np.isfinite(hits.t)), f"{where}: hit mask and finite depth disagree"


@pytest.fixture(scope="module")
def fits():
    from tests.hard_cases.test_surface_start_rays import quick_fit

    shape = load_shape({"name": "torus"})
    fits = {}
    for family in FAMILIES:
        if family == "mesh":
            if not has_warp():
                continue
            fits[family] = quick_fit(family, shape, backend="warp")[0]
        else:
            # the GAN's generator (~2 MFLOP a point) needs ~150 steps before its torus has a surface to trace
            work = {"steps": 150, "seconds": 300.0} if family == "gan_sdf" else {"seconds": 3.0}
            fits[family] = quick_fit(family, shape, **work)[0]
    return fits


@pytest.mark.parametrize("family", FAMILIES)
def test_same_answers_on_the_device_as_on_the_cpu(fits, family):
    if family not in fits:
        pytest.skip('mesh on the device needs NVIDIA Warp (pip install -e ".[gpu]")')
    rep = fits[family]
    o, d = rays()
    on_cpu = rep.to("cpu").intersect(o, d)
    on_dev = rep.to(DEVICE).intersect(o, d)
    rep.to("cpu")
    assert_no_nan(on_cpu, f"{family} cpu")
    assert_no_nan(on_dev, f"{family} {DEVICE}")
    agree_min, dt_max = TOLERANCE[family]
    assert on_cpu.hit.mean() > 0.1, f"{family}: the quick fit hit only {on_cpu.hit.mean():.2f} of the rays"
    agree = (on_cpu.hit == on_dev.hit).mean()
    assert agree >= agree_min, f"{family}: hit masks agree on {agree:.4f} of the rays"
    both = on_cpu.hit & on_dev.hit
    dt = np.abs(on_cpu.t[both] - on_dev.t[both])
    assert np.percentile(dt, 99) < dt_max, f"{family}: |t_cpu - t_{DEVICE}| p99 {np.percentile(dt, 99):.2e}"
    valid = both & on_cpu.normal_valid & on_dev.normal_valid
    cos = np.einsum("ij,ij->i", on_cpu.normal[valid], on_dev.normal[valid])
    assert np.percentile(cos, 1) > 0.999, f"{family}: normals differ (1st percentile cos {np.percentile(cos, 1):.4f})"


def test_ddf_device_depth_in_reduced_precision_and_compiled(fits):
    """ddf_infer.DDFDepth on the device: fp32 equals DDF.intersect; bf16, compiled bf16 and the fused MLP stay close to it."""
    if "ddf" not in fits:
        pytest.skip("no ddf family")
    from ddfbench.models.ddf.infer import DDFDepth

    rep = fits["ddf"].to(DEVICE)
    o, d = rays()
    ref = rep.intersect(o, d, normals=False)
    od, dd = torch.as_tensor(o, device=DEVICE), torch.as_tensor(d, device=DEVICE)
    variants = {"fp32": DDFDepth(rep, "fp32", chunk=700), "bf16": DDFDepth(rep, "bf16", chunk=700)}
    if DEVICE.startswith("cuda"):  # a CPU compile takes minutes on a small machine
        variants["bf16 compiled"] = DDFDepth(rep, "bf16", compiled=True, chunk=700)
        variants["bf16 fused MLP, compiled"] = DDFDepth(rep, "bf16", compiled=True, fused="mlp", chunk=700)
        variants["bf16 fused depth"] = DDFDepth(rep, "bf16", fused="depth", chunk=700)
    for name, depth in variants.items():
        t = depth(od, dd).cpu().numpy()
        assert not np.isnan(t).any(), name
        hit = np.isfinite(t)
        both = hit & ref.hit
        if name == "fp32":
            assert (hit == ref.hit).mean() > 0.999 and np.abs(t[both] - ref.t[both]).max() < 1e-4
        else:
            assert (hit == ref.hit).mean() > 0.98, name
            assert np.abs(t[both] - ref.t[both]).mean() < 5e-3, name
    rep.to("cpu")


def test_warp_caster_on_the_device_equals_the_cpu():
    pytest.importorskip("warp", reason='NVIDIA Warp not installed (pip install -e ".[gpu]")')
    from ddfbench.truth.warp_cast import WarpCaster

    mesh = load_shape({"name": "bunny"}).mesh
    o, d = incoherent_rays(100_000, seed=4)
    t_cpu, f_cpu, n_cpu = WarpCaster(mesh.vertices, mesh.faces, "cpu").cast(o, d)
    t_dev, f_dev, n_dev = WarpCaster(mesh.vertices, mesh.faces, DEVICE).cast(o, d)
    assert np.array_equal(np.isfinite(t_cpu), np.isfinite(t_dev)) and not np.isnan(t_dev).any()
    hit = np.isfinite(t_cpu)
    assert np.abs(t_cpu[hit] - t_dev[hit]).max() < 1e-5
    assert (f_cpu[hit] == f_dev[hit]).mean() > 0.999  # a ray through a shared edge may name either face


@pytest.mark.parametrize("family", [f for f in ("ddf", "neural_sdf", "grid_sdf", "gan_sdf", "mesh") if has_family(f)])
def test_run_end_to_end_on_the_device(family, tmp_path):
    """train.device=<device>: fit, extract, render and score a run; its depth images hold no NaN."""
    from ddfbench.run.runner import run

    extra = (["model.backend=warp"] if family == "mesh" and has_warp() else []) + [f"oracle.backend={ORACLE_BACKEND}"]
    rec = run(compose(f"model={family}", "shape=sphere", "scene=depth", f"train.device={DEVICE}",
                      "train.max_steps=30", "train.max_seconds=20", "train.n_probes=0", "eval.mesh_resolution=24",
                      "scene.width=24", "scene.height=24", *extra, out_dir=tmp_path))
    assert rec["status"] == "ok", rec["error"]
    assert rec["env"]["device"] == DEVICE
    images = glob.glob(os.path.join(tmp_path, "**", "*.npy"), recursive=True)
    assert images, "the run wrote no raw render arrays"
    for path in images:
        a = np.load(path)
        assert not (np.issubdtype(a.dtype, np.floating) and np.isnan(a).any()), f"NaN in {os.path.basename(path)}"
