"""python -m ddfbench.bench.fused_parts [--device cuda] [--rays N] [--repeats 9] [--out FILE.json]

Where the fused DDF's time goes (issue 17's 1e9 rays/s goal). On one device, in one process (synchronized,
warm-up excluded, medians; ddfbench.bench.timing), for the ddf_tuned network with random weights (the time
does not depend on them) on N incoherent rays, it times:
- `encode`: the compiled box entry + encoding pass before the kernel (writes the kernel's (N, K0) bf16 input);
- `kernel`: the Triton MLP (ddfbench.models.ddf.fused);
- `finish`: the compiled hit rule after it;
- `whole`: DDFDepth(fused="mlp", compiled=True): the three parts, chunked as the race does;
- `depth_kernel`: DDFDepth(fused="depth"): the whole answer as one kernel (box entry, encoding, MLP, hit rule);
- `bare_bf16`: the network's layer-by-layer forward under bf16 autocast, on the same inputs;
- `gemm_bf16`: one (N, K) x (K, width) bf16 product with K chosen so that it does the MLP's FLOPs: what the
  device's matrix units give at this kind of shape.
Each part's rays/s and, for the kernels and the product, TFLOP/s (2 x multiply-adds of the padded layers), and the
block size and warps the autotuner chose for each kernel.
Needs CUDA and Triton (or TRITON_INTERPRET=1 on the CPU, for a check of the script itself).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import sys

import torch

from ddfbench.bench.context import model_preset
from ddfbench.bench.timing import measure_side_by_side
from ddfbench.bench.views import incoherent_rays
from ddfbench.models.ddf import DDF
from ddfbench.models.ddf.infer import DDFDepth


def kernel_flops(mlp) -> int:
    """FLOPs a ray of the fused kernel as it computes them (padded input, hidden layers, head)."""
    return 2 * (mlp.k0 * mlp.width + mlp.hidden * mlp.width * mlp.width + mlp.width * mlp.n_out)


def dense_bf16_tflops(device: str, n: int = 8192, repeats: int = 20, warmup: int = 300) -> float:
    """TFLOP/s of one dense n x n x n bf16 product on random data (median of `repeats` after `warmup` untimed
    products, ~0.4 s on an H100, so the clocks have ramped up): the matrix units' practical ceiling that a
    kernel's rate is read against (issue 51: 2 n^3 FLOPs a product)."""
    a = torch.randn(n, n, device=device, dtype=torch.bfloat16)
    b = torch.randn(n, n, device=device, dtype=torch.bfloat16)
    timing = measure_side_by_side({"gemm": lambda: a @ b}, repeats, warmup, device=device)["gemm"][1]
    return 2.0 * n**3 / timing.median_s / 1e12


def parts(device: str, rays: int, repeats: int, compiled: bool = True, chunk: int = 1 << 21, seed: int = 0) -> dict:
    """{part: {"median_s", "iqr_s", "rays_per_s", "tflops"?}, "n_rays", "flops_per_ray", ...} for N = rays
    (compiled: the passes around the kernel through torch.compile, as the race runs them)."""
    from ddfbench.models.ddf.fused import config  # needs Triton: imported once the caller has checked

    torch.manual_seed(seed)
    rep = DDF(model_preset("ddf_tuned")).to(device)
    depth = DDFDepth(rep, "bf16", compiled=compiled, fused="mlp", chunk=chunk)
    one_kernel = DDFDepth(rep, "bf16", fused="depth", chunk=chunk)
    mlp = depth.mlp
    o, d = (torch.as_tensor(a, device=device) for a in incoherent_rays(rays, seed=seed + 1))
    x, s0, t_entry, t_exit, meets = depth.encode(o, d)
    y = mlp(x)
    feats = rep.net.features(o + t_entry[:, None] * d, d)[0]
    flops = kernel_flops(mlp)
    k = max(16, round(flops / (2 * mlp.width)) // 16 * 16)
    a = torch.randn(rays, k, device=device, dtype=torch.bfloat16)
    b = torch.randn(k, mlp.width, device=device, dtype=torch.bfloat16)

    @torch.no_grad()
    def bare() -> None:
        with torch.autocast(device.split(":")[0], dtype=torch.bfloat16):
            rep.net.out(rep.net.body(feats))

    fns = {"encode": lambda: depth.encode(o, d), "kernel": lambda: mlp(x),
           "finish": lambda: depth.finish(y, s0, t_entry, t_exit, meets), "whole": lambda: depth(o, d),
           "depth_kernel": lambda: one_kernel(o, d),
           "bare_bf16": bare, "gemm_bf16": lambda: a @ b}
    out = {"n_rays": rays, "flops_per_ray": flops, "device": device, "compiled": compiled,
           "gpu": torch.cuda.get_device_name(torch.device(device)) if device.startswith("cuda") else None}
    for name, (_, timing) in measure_side_by_side(fns, repeats, 1, device=device).items():
        out[name] = {"median_s": timing.median_s, "iqr_s": timing.iqr_s, "rays_per_s": timing.rate(rays)}
        if name in ("kernel", "depth_kernel", "gemm_bf16"):
            out[name]["tflops"] = timing.rate(rays) * (2 * k * mlp.width if name == "gemm_bf16" else flops) / 1e12
    out["configs"] = {"mlp": config("mlp"), "depth": config("depth")}  # both last tuned on these N rays
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ddfbench.bench.fused_parts", description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--rays", type=int, default=1 << 21)
    ap.add_argument("--repeats", type=int, default=9)
    ap.add_argument("--eager", action="store_true", help="the passes around the kernel not compiled")
    ap.add_argument("--out", default=None, help="JSON file for the figures")
    args = ap.parse_args(argv)
    if importlib.util.find_spec("triton") is None:
        print("ddfbench.bench.fused_parts: needs Triton (it comes with CUDA builds of torch)", file=sys.stderr)
        return 2
    result = parts(args.device, args.rays, args.repeats, compiled=not args.eager)
    for name, v in result.items():
        if isinstance(v, dict) and "median_s" in v:
            extra = f"  {v['tflops']:.1f} TFLOP/s" if "tflops" in v else ""
            print(f"{name:10s} {v['median_s'] * 1e3:9.3f} ms  {v['rays_per_s']:.3g} rays/s{extra}")
    print(f"autotuned: {result['configs']}")
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(result, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
