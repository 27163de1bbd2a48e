"""ddfbench.models.ddf.fused: the DDF's MLP as one Triton kernel gives the layer-by-layer bf16 answer.

On CUDA (`pytest -m gpu`) the kernel runs on the device; without CUDA, where Triton is installed, the same
checks run in one subprocess under TRITON_INTERPRET=1 (Triton's CPU interpreter; the variable must be set
before the kernel is defined), each test here asserting its own outcome there. Without either they skip.
"""

import importlib.util
import json
import os
import subprocess
import sys
import tempfile
from xml.etree import ElementTree

import pytest
import torch
from torch import nn

from ddfbench.bench.context import model_preset
from ddfbench.models.ddf import DDF

HAS_TRITON = importlib.util.find_spec("triton") is not None
CUDA = torch.cuda.is_available()
INTERPRETED = os.environ.get("TRITON_INTERPRET") == "1"
DEVICE = "cuda" if CUDA else "cpu"
pytestmark = pytest.mark.skipif(not HAS_TRITON, reason="Triton is not installed (it comes with CUDA builds of torch)")

# (width, depth, pos_freqs, dir_freqs, extra): ddf_tuned, the pareto c1 and c3 levels, a body with no hidden
# layer; points in place of the ray parameterization with a one-output (clamp) head; weight norm
NETWORKS = [(128, 4, 5, 1, {}), (64, 3, 5, 1, {}), (256, 6, 5, 1, {}), (64, 1, 0, 0, {}),
            (64, 2, 3, 1, {"param": "point", "visibility": "clamp", "loss": "clamp"}), (64, 3, 2, 1, {"weight_norm": True})]
IDS = ["128x4", "64x3", "256x6", "64x1", "point-clamp", "weight-norm"]


def random_rep(width: int, depth: int, pos_freqs: int, dir_freqs: int, extra: dict, seed: int = 0) -> DDF:
    torch.manual_seed(seed)
    rep = DDF(model_preset("ddf_tuned", width=width, depth=depth, pos_freqs=pos_freqs, dir_freqs=dir_freqs, **extra))
    with torch.no_grad():  # biases away from 0, so that a dropped bias shows
        for m in rep.net.modules():
            if isinstance(m, nn.Linear):
                m.bias.uniform_(-0.5, 0.5)
    return rep.to(DEVICE)


def rays(n: int, seed: int = 1) -> tuple[torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    o = (torch.rand(n, 3, generator=g) * 2.4 - 1.2)
    d = nn.functional.normalize(torch.randn(n, 3, generator=g), dim=1)
    return o.to(DEVICE), d.to(DEVICE)


def layerwise_bf16(net, feats: torch.Tensor) -> torch.Tensor:
    """The kernel's arithmetic written layer by layer: bf16 inputs and weights, fp32 sums and bias, ReLU, bf16
    (autocast differs in adding a bf16 bias and rounding the head to bf16: the fp32 comparison covers that)."""
    h = feats.to(torch.bfloat16).float()
    linears = [m for m in net.body if isinstance(m, nn.Linear)]
    for m in linears:
        h = torch.relu(h @ m.weight.to(torch.bfloat16).float().t() + m.bias.float()).to(torch.bfloat16).float()
    return h @ net.out.weight.to(torch.bfloat16).float().t() + net.out.bias.float()


def box_rays(n: int, seed: int) -> tuple[torch.Tensor, torch.Tensor]:
    """n rays that meet the field box: two thirds from origins inside it in random directions, a third from
    origins 2.5 from the centre aimed at points inside it (so their box entry is not at the origin)."""
    g = torch.Generator().manual_seed(seed)
    o = torch.rand(n, 3, generator=g) * 2.2 - 1.1
    far = torch.arange(n) % 3 == 0
    o[far] = nn.functional.normalize(torch.randn(int(far.sum()), 3, generator=g), dim=1) * 2.5
    d = nn.functional.normalize(torch.randn(n, 3, generator=g), dim=1)
    d[far] = nn.functional.normalize(torch.rand(int(far.sum()), 3, generator=g) * 1.8 - 0.9 - o[far], dim=1)
    return o.to(DEVICE), d.to(DEVICE)


def responsive(rep: DDF, o: torch.Tensor, d: torch.Tensor) -> DDF:
    """rep with every body weight x2.5 (a random ReLU stack otherwise answers nearly the same for every input:
    for 256 x 6 the logits spread by ~0.002) and its output biases shifted so that the rays o + t d get
    distances around half their chord inside the box and about half of them count as visible."""
    from ddfbench.core.geometry import box_entry

    t_entry, t_exit, meets = box_entry(o, d, rep.domain)
    with torch.no_grad():
        for m in rep.net.body:
            if isinstance(m, nn.Linear):
                m.weight.mul_(2.5)
        dist, logit = rep.net(o[meets] + t_entry[meets, None] * d[meets], d[meets])
        rep.net.out.bias[0] -= (dist - (t_exit - t_entry)[meets] / 2).median()
        if logit is not None:
            rep.net.out.bias[1] -= logit.median()
    return rep


_INTERPRETED_OUTCOMES: dict[str, str] = {}  # test name -> "" (passed) or what went wrong, filled by one subprocess


def run_interpreted(test: str) -> None:
    """Assert that this file's test `test` passed under Triton's CPU interpreter: the first call runs the whole
    file once in a subprocess with TRITON_INTERPRET=1 (one interpreter start-up, not one a test)."""
    if not _INTERPRETED_OUTCOMES:
        with tempfile.TemporaryDirectory() as tmp:
            xml = os.path.join(tmp, "junit.xml")
            out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", __file__,
                                  f"--junitxml={xml}"], env={**os.environ, "TRITON_INTERPRET": "1"},
                                 capture_output=True, text=True, timeout=1200)
            assert os.path.exists(xml), out.stdout[-3000:] + out.stderr[-2000:]
            for case in ElementTree.parse(xml).iter("testcase"):
                bad = [f"{c.tag}: {c.get('message', '')}\n{c.text or ''}" for c in case if c.tag in ("failure", "error", "skipped")]
                _INTERPRETED_OUTCOMES[case.get("name")] = "\n".join(bad)
    assert test in _INTERPRETED_OUTCOMES, f"{test}: not run by the interpreted subprocess"
    assert _INTERPRETED_OUTCOMES[test] == "", _INTERPRETED_OUTCOMES[test][-4000:]


def needs_a_kernel_runner(test: str) -> bool:
    """True where the test body should run here (CUDA, or already interpreted); else it runs interpreted."""
    if CUDA or INTERPRETED:
        return True
    run_interpreted(test)
    return False


@pytest.mark.gpu
@pytest.mark.parametrize("shape", NETWORKS, ids=IDS)
def test_fused_mlp_equals_the_layerwise_bf16_forward(shape):
    if not needs_a_kernel_runner(f"test_fused_mlp_equals_the_layerwise_bf16_forward[{IDS[NETWORKS.index(shape)]}]"):
        return
    from ddfbench.models.ddf.fused import FusedMLP

    rep = random_rep(*shape)
    o, d = rays(1000)  # not a multiple of the block: the last block is masked
    feats, _ = rep.net.features(o, d)
    mlp = FusedMLP(rep.net)
    y = mlp(mlp.pad(feats))
    ref = layerwise_bf16(rep.net, feats)
    with torch.no_grad():
        y32 = rep.net.out(rep.net.body(feats))
    assert y.shape == (1000, rep.net.out.out_features) and y.dtype == torch.float32
    scale = ref.abs().mean()
    # the same arithmetic up to the order of fp32 sums (a bf16 rounding may flip): ~1 bf16 step
    assert (y - ref).abs().max() < 0.02 * scale + 1e-3, float((y - ref).abs().max())
    # and as close to the fp32 network as bf16 allows
    assert (y - y32).abs().mean() < 0.02 * scale, float((y - y32).abs().mean())
    assert mlp(mlp.pad(feats[:0])).shape == (0, y.shape[1])


@pytest.mark.gpu
def test_fused_depth_answers_like_the_bf16_depth():
    """DDFDepth(fused) against DDFDepth(bf16 autocast) of the same network: same hits, close depths."""
    if not needs_a_kernel_runner("test_fused_depth_answers_like_the_bf16_depth"):
        return
    from ddfbench.models.ddf.infer import DDFDepth

    rep = random_rep(128, 4, 5, 1, {})
    o, d = rays(3000, seed=2)
    t_ref = DDFDepth(rep, "fp32", chunk=1024)(o, d)
    t_fused = DDFDepth(rep, "bf16", fused="mlp", chunk=1024)(o, d)
    hit, ref_hit = torch.isfinite(t_fused), torch.isfinite(t_ref)
    assert ref_hit.float().mean() > 0.1  # the random network answers "hit" on ~18 % of these rays
    assert (hit == ref_hit).float().mean() > 0.97
    both = hit & ref_hit
    assert (t_fused[both] - t_ref[both]).abs().mean() < 0.02


@pytest.mark.gpu
@pytest.mark.parametrize("shape", NETWORKS, ids=IDS)
def test_one_kernel_depth_answers_like_the_fused_mlp_between_torch_passes(shape):
    """FusedDepth (box entry, encoding, MLP and hit rule in one kernel) against DDFDepth(fused="mlp") (the
    same MLP kernel, the rest in torch) and the fp32 answer, on rays from inside and outside the box that
    meet it, 10-90 % of them hits."""
    if not needs_a_kernel_runner(f"test_one_kernel_depth_answers_like_the_fused_mlp_between_torch_passes[{IDS[NETWORKS.index(shape)]}]"):
        return
    from ddfbench.models.ddf.infer import DDFDepth

    o, d = box_rays(1500, seed=3)
    rep = responsive(random_rep(*shape), o, d)
    t_one = DDFDepth(rep, "bf16", fused="depth", chunk=1000)(o, d)  # two chunks, the second masked
    t_mlp = DDFDepth(rep, "bf16", fused="mlp", chunk=1000)(o, d)
    t_ref = DDFDepth(rep, "fp32", chunk=1000)(o, d)
    hit, mlp_hit, ref_hit = torch.isfinite(t_one), torch.isfinite(t_mlp), torch.isfinite(t_ref)
    assert t_one.shape == (1500,) and not t_one.isnan().any()
    assert 0.1 < ref_hit.float().mean() < 0.9
    both, both_ref, mlp_ref = hit & mlp_hit, hit & ref_hit, mlp_hit & ref_hit
    # the same arithmetic but for the order of fp32 operations before the bf16 rounding of the inputs (and the
    # x2.5 weights amplify a flipped bf16 step): a few flipped hits, depths within a bf16 step or so
    assert (hit == mlp_hit).float().mean() > 0.99
    assert (t_one[both] - t_mlp[both]).abs().mean() < 5e-3
    # and no further from the fp32 answer than the MLP kernel's path is
    assert (hit == ref_hit).float().mean() >= (mlp_hit == ref_hit).float().mean() - 0.005
    assert (t_one[both_ref] - t_ref[both_ref]).abs().mean() < 1.5 * (t_mlp[mlp_ref] - t_ref[mlp_ref]).abs().mean() + 1e-3


@pytest.mark.gpu
@pytest.mark.parametrize("param", ["ray", "point"])
def test_one_kernel_depth_keeps_the_box_and_hit_rule(param):
    """A network that answers distance c and "visible" everywhere (zero weights, output biases (c, 5)): the
    kernel's t is the box entry + c (ray: + c - s0, s0 = x.d at the entry) where that lies in the box and past
    min_hit_distance, else inf; rays with zero direction components and origins on faces included."""
    if not needs_a_kernel_runner(f"test_one_kernel_depth_keeps_the_box_and_hit_rule[{param}]"):
        return
    import numpy as np

    from ddfbench.core.geometry import box_entry
    from ddfbench.models.ddf.fused import FusedDepth

    rep = random_rep(64, 2, 3, 1, {"param": param})
    with torch.no_grad():
        for m in [*rep.net.body, rep.net.out]:
            if isinstance(m, nn.Linear):
                m.weight.zero_()
                m.bias.zero_()
        rep.net.out.bias.copy_(torch.tensor([0.3, 5.0]))
    o, d = rays(600, seed=4)
    o = o * 1.4
    h = rep.domain
    nan = float("nan")  # a NaN anywhere in a ray: a miss, as in torch (the last two rays)
    o[:8] = torch.tensor([[h, 0.0, 0.0], [-h, 0.3, 0.2], [0.0, h, -h], [0.2, 0.1, 2.0], [0.5, -0.5, 0.0], [2.0, 2.0, 2.0],
                          [nan, 0.0, 0.0], [0.1, 0.1, -2.0]])
    d[:8] = torch.tensor([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0],
                          [0.0, 0.0, 1.0], [nan, 0.0, 1.0]])
    t = FusedDepth(rep)(o, d).cpu().double().numpy()
    o64, d64 = o.cpu().double().numpy(), d.cpu().double().numpy()
    t_entry, t_exit, meets = box_entry(o64, d64, float(np.float32(h)))  # the box as fp32 sees it: faces included
    x = o64 + np.where(meets, t_entry, 0.0)[:, None] * d64
    s0 = (x * d64).sum(1)
    dist = np.maximum(0.3 - s0, 0.0) if param == "ray" else np.full(len(o64), 0.3)
    want = t_entry + dist
    want = np.where(meets & (want > float(rep.cfg["min_hit_distance"])) & (want <= t_exit), want, np.inf)
    # bf16 output head: c and 5 are exact; s0 enters in fp32
    assert np.isinf(want[6:8]).all() and not np.isnan(t).any()
    assert np.array_equal(np.isinf(t), np.isinf(want)), np.flatnonzero(np.isinf(t) != np.isinf(want))[:10]
    assert 0.05 < np.isfinite(want).mean() < 0.95
    fin = np.isfinite(want)
    assert np.abs(t[fin] - want[fin]).max() < 1e-5


def test_what_is_not_fused_is_refused():
    from ddfbench.models.ddf.fused import FusedDepth, FusedMLP, supported, supported_depth
    from ddfbench.models.ddf.infer import DDFDepth

    base = model_preset("ddf_tuned")
    assert supported(DDF(base).net) is None
    assert "softplus" in supported(DDF({**base, "activation": "softplus"}).net)
    assert "width 512" in supported(DDF({**base, "width": 512}).net)
    assert "width 32" in supported(DDF({**base, "width": 32}).net)
    assert "line grid" in supported(DDF({**base, "line_grid_points": 4}).net)
    assert "angles" in supported_depth(DDF({**base, "direction": "angles"}).net)
    assert supported_depth(DDF(base).net) is None and "width 512" in supported_depth(DDF({**base, "width": 512}).net)
    with pytest.raises(ValueError, match="width 512"):
        FusedMLP(DDF({**base, "width": 512}).net)
    with pytest.raises(ValueError, match="angles"):
        FusedDepth(DDF({**base, "direction": "angles"}))
    with pytest.raises(ValueError, match="bf16 only"):
        DDFDepth(DDF(base), "fp32", fused="depth")
    with pytest.raises(ValueError, match="fused 'yes'"):
        DDFDepth(DDF(base), "bf16", fused="yes")


@pytest.mark.gpu
def test_fused_parts_times_every_part_and_counts_the_kernel_flops(tmp_path):
    """python -m ddfbench.bench.fused_parts: each part timed, the kernel's FLOPs those of ddf_tuned's padded layers."""
    if not needs_a_kernel_runner("test_fused_parts_times_every_part_and_counts_the_kernel_flops"):
        return
    from ddfbench.bench.fused_parts import main

    out = tmp_path / "parts.json"
    assert main(["--device", DEVICE, "--rays", "700", "--repeats", "1", "--out", str(out)]
                + ([] if CUDA else ["--eager"])) == 0  # a CPU compile takes minutes
    doc = json.loads(out.read_text())
    # ddf_tuned: 4 position + 3 direction channels, 5 and 1 octaves -> 53 inputs, padded to 64; 128 x 4; 2 outputs
    assert doc["flops_per_ray"] == 2 * (64 * 128 + 3 * 128 * 128 + 128 * 2)
    for part in ("encode", "kernel", "finish", "whole", "depth_kernel", "bare_bf16", "gemm_bf16"):
        assert doc[part]["median_s"] > 0 and doc[part]["rays_per_s"] > 0, part
    assert doc["kernel"]["tflops"] > 0 and doc["gemm_bf16"]["tflops"] > 0 and doc["depth_kernel"]["tflops"] > 0
    assert set(doc["configs"]) == {"mlp", "depth"}
    assert all(("BLOCK" in c and "warps" in c) if CUDA else c.startswith("interpreted") for c in doc["configs"].values())
