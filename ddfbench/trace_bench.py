"""Benchmark: the sphere tracer against the naive loop, and the level-set grid build against brute force.

    python -m ddfbench.trace_bench [--shape bunny] [--size 256] [--train-seconds 150] [--model path.pt]
                                   [--naive-steps 64] [--grids 32 64 128] [--skip-trace] [--skip-grid]

Tracer: a neural SDF of the shape (trained here for --train-seconds on oracle SDF
samples, or loaded from --model) renders a size^2 pinhole view; the tracer
(ddfbench.trace, active-set compaction) is compared with the naive loop (every
ray evaluated every step, the field called twice per step: once for the step, once
for the convergence test) on field evaluations per pixel and wall time, and on
their agreement. Grid: build time of levelset_sdf_grid against exact_sdf_grid at
each resolution, and the largest error against the exact grid inside the exact
band (|d| <= 2 steps), in a wider shell (|d| <= 8 steps) and overall.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from ddfbench import levelset
from ddfbench.oracle import Oracle
from ddfbench.representation import Budget, FitData
from ddfbench.samples import Samples
from ddfbench.shapes import load_shape
from ddfbench.trace import TraceOptions, TorchField, clip_to_box, sphere_trace


def oracle_sdf_samples(mesh, oracle: Oracle, n: int, seed: int, domain: float = 0.6) -> Samples:
    """n SDF samples labelled by the oracle: 45% surface + N(0, 0.005), 45% surface + N(0, 0.03), 10% uniform in the box."""
    rng = np.random.default_rng(seed)
    n_near = int(0.45 * n)
    surface = np.asarray(mesh.sample(2 * n_near, seed=int(rng.integers(2**31))), np.float32)
    sigma = np.r_[np.full(n_near, 0.005), np.full(n_near, 0.03)].astype(np.float32)[:, None]
    near = surface + rng.normal(size=surface.shape).astype(np.float32) * sigma
    uniform = rng.uniform(-domain, domain, (n - 2 * n_near, 3)).astype(np.float32)
    x = np.clip(np.concatenate([near, uniform]), -domain, domain)
    return Samples(x=x, sdf=oracle.signed_distance(x), meta={"strategy": "oracle_sdf", "seed": seed})


def pinhole_rays(size: int, eye=(0.9, 0.5, 1.2), fov_deg: float = 40.0) -> tuple[np.ndarray, np.ndarray]:
    """size^2 rays of a camera at `eye` looking at the origin (y up): origins, unit directions (size^2, 3)."""
    eye = np.asarray(eye, np.float32)
    fwd = -eye / np.linalg.norm(eye)
    right = np.cross(fwd, [0.0, 1.0, 0.0]).astype(np.float32)
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    s = np.tan(np.radians(fov_deg) / 2) * ((np.arange(size) + 0.5) / size * 2 - 1)
    u, v = np.meshgrid(s, -s)
    d = fwd + u.reshape(-1, 1) * right + v.reshape(-1, 1) * up
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    return np.broadcast_to(eye, d.shape).copy(), d


def naive_trace(field: TorchField, origins: np.ndarray, directions: np.ndarray, domain: float,
                eps: float = 1e-5, eps_abs: float = 1e-6, max_steps: int = 256) -> tuple[np.ndarray, int]:
    """The baseline loop: every ray every step, field evaluated twice per step. Returns (t (inf unless hit), evals)."""
    o, d = torch.from_numpy(origins), torch.from_numpy(directions)
    t_enter, t_exit = clip_to_box(o, d, domain)
    t = t_enter.clone()
    evals = 0
    with torch.no_grad():
        for _ in range(max_steps):
            t = t + field(o + t[:, None] * d)
            f = field(o + t[:, None] * d)
            evals += 2 * len(t)
        hit = (f.abs() < eps * t + eps_abs) & (t_enter <= t_exit) & (t <= t_exit)
    return torch.where(hit, t, torch.full_like(t, float("inf"))).numpy(), evals


def bench_trace(shape_name: str, size: int, train_seconds: float, model_path: str | None, naive_steps: int) -> None:
    from ddfbench.models.neural_sdf import NeuralSDF

    shape = load_shape({"name": shape_name})
    oracle = Oracle(shape.mesh)
    if model_path:
        rep = NeuralSDF.load(model_path)
    else:
        rep = NeuralSDF({})
        t0 = time.perf_counter()
        samples = oracle_sdf_samples(shape.mesh, oracle, 500_000, seed=0)
        print(f"samples: {len(samples)} in {time.perf_counter() - t0:.1f}s")
        stats = rep.fit(FitData(samples, shape.mesh, oracle), Budget(max_steps=10**9, max_seconds=train_seconds))
        print(f"neural_sdf: {rep.n_params()} params, {stats.steps} steps in {stats.seconds:.0f}s, status {stats.status}")
    o, d = pinhole_rays(size)
    n = len(o)
    gt_t = oracle.hit_distance(o, d)
    rows = []
    for name, run in (
        ("tracer omega=1.0", lambda: sphere_trace(rep.field, o, d, rep.domain, TraceOptions(omega=1.0))),
        ("tracer omega=1.6", lambda: sphere_trace(rep.field, o, d, rep.domain, TraceOptions(omega=1.6))),
        (f"naive {naive_steps} steps", lambda: naive_trace(rep.field, o, d, rep.domain, max_steps=naive_steps)),
    ):
        t0 = time.perf_counter()
        out = run()
        wall = time.perf_counter() - t0
        t, evals = (out.t, out.field_evals) if hasattr(out, "t") else out
        hit = np.isfinite(t)
        agree = float((hit == np.isfinite(gt_t)).mean())
        both = hit & np.isfinite(gt_t)
        depth_err = float(np.median(np.abs(t[both] - gt_t[both]))) if both.any() else float("nan")
        undecided = int((out.status == 2).sum()) if hasattr(out, "status") else 0
        rows.append((name, evals / n, wall, hit.mean(), agree, depth_err, undecided))
    print(f"\n{shape_name} neural SDF, {size}x{size} rays, threads={torch.get_num_threads()}")
    print(f"{'method':18s} {'evals/px':>9s} {'wall s':>8s} {'hit %':>6s} {'mask agree GT':>13s} {'median |dt| vs GT':>18s} {'undecided':>9s}")
    for r in rows:
        print(f"{r[0]:18s} {r[1]:9.1f} {r[2]:8.2f} {100 * r[3]:6.1f} {100 * r[4]:12.2f}% {r[5]:18.2e} {r[6]:9d}")


def bench_grid(shape_name: str, resolutions: list[int], domain: float = 0.6) -> None:
    shape = load_shape({"name": shape_name})
    oracle = Oracle(shape.mesh)
    print(f"\n{shape_name} grid build, threads={torch.get_num_threads()}")
    print(f"{'N':>4s} {'exact s':>8s} {'levelset s':>10s} {'speedup':>7s} {'exact nodes':>11s} "
          f"{'max err band':>12s} {'max err 8h':>10s} {'max err all':>11s} {'mean err all':>12s} {'sign flips':>10s}")
    for n in resolutions:
        t0 = time.perf_counter()
        exact = levelset.exact_sdf_grid(oracle, n, domain)
        t1 = time.perf_counter()
        grid, info = levelset.levelset_sdf_grid(oracle, n, domain)
        t2 = time.perf_counter()
        h = 2 * domain / (n - 1)
        err = np.abs(grid - exact)
        band, shell = np.abs(exact) <= 2 * h, np.abs(exact) <= 8 * h
        flips = int((np.sign(grid) != np.sign(exact)).sum())
        print(f"{n:4d} {t1 - t0:8.2f} {t2 - t1:10.2f} {(t1 - t0) / (t2 - t1):7.1f} {info['exact_nodes']:11d} "
              f"{err[band].max():12.2e} {err[shell].max():10.2e} {err.max():11.2e} {err.mean():12.2e} {flips:10d}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shape", default="bunny")
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--train-seconds", type=float, default=150.0)
    ap.add_argument("--model", default=None, help="a saved neural_sdf .pt instead of training one")
    ap.add_argument("--naive-steps", type=int, default=64, help="iterations of the naive loop (its cost is 2 x rays x this)")
    ap.add_argument("--grids", type=int, nargs="+", default=[32, 64, 128])
    ap.add_argument("--skip-trace", action="store_true")
    ap.add_argument("--skip-grid", action="store_true")
    args = ap.parse_args()
    if not args.skip_grid:
        bench_grid(args.shape, args.grids)
    if not args.skip_trace:
        bench_trace(args.shape, args.size, args.train_seconds, args.model, args.naive_steps)


if __name__ == "__main__":
    main()
