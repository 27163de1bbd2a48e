"""Surface-sampling throughput beside bare open3d ray casting, measured in the same process.

python -m ddfbench.sampling.bench [--shape bunny] [--s 10] [--face-mode per_face] [--rays 4000000]

Prints labels/s of surface sampling (s_fc = s_dr = s_p = --s) and rays/s of open3d's bare
RaycastingScene.cast_rays on random rays in the field box (median of 3, before and after the
sampling run, the two medians averaged), and their ratio.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np
import open3d as o3d
import yaml

from ddfbench.oracle import Oracle
from ddfbench.sampling import build
from ddfbench.shapes import load_shape

CONF = os.path.join(os.path.dirname(__file__), "..", "..", "conf", "sampling", "surface.yaml")


def bare_cast_rate(mesh, n: int, half: float, seed: int = 0) -> float:
    """Median rays/s of open3d cast_rays over 3 calls of n random rays (origins in the box, uniform directions)."""
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32)),
                        o3d.core.Tensor(np.asarray(mesh.faces, np.uint32)))
    rng = np.random.default_rng(seed)
    d = rng.standard_normal((n, 3)).astype(np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rays = o3d.core.Tensor(np.hstack([rng.uniform(-half, half, (n, 3)).astype(np.float32), d]))
    scene.cast_rays(rays[:1000])  # builds the BVH
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        scene.cast_rays(rays)
        times.append(time.perf_counter() - t0)
    return n / float(np.median(times))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shape", default="bunny")
    ap.add_argument("--s", type=int, default=10, help="s_fc = s_dr = s_p")
    ap.add_argument("--face-mode", default="per_face", choices=("per_face", "total"))
    ap.add_argument("--rays", type=int, default=4_000_000, help="rays per bare cast_rays call")
    args = ap.parse_args()
    with open(CONF) as f:
        cfg = yaml.safe_load(f)
    cfg.update(box=0.6, face_mode=args.face_mode, s_fc=args.s, s_dr=args.s, s_p=args.s)
    shape = load_shape({"name": args.shape})
    before = bare_cast_rate(shape.mesh, args.rays, 0.6)
    with tempfile.TemporaryDirectory() as tmp:
        _, _, info = build(shape, Oracle(shape.mesh), cfg, "rays", 0, tmp)
    after = bare_cast_rate(shape.mesh, args.rays, 0.6)
    bare = 0.5 * (before + after)
    rate = info["samples_per_s"]
    print(f"surface sampling {args.shape} ({len(shape.mesh.faces)} faces, {args.face_mode} s_fc=s_dr=s_p={args.s}): "
          f"{info['n_samples']:.3g} labels in {info['sampling_s']:.1f} s = {rate / 1e6:.2f} M labels/s; "
          f"open3d cast_rays {bare / 1e6:.2f} M rays/s (before {before / 1e6:.2f}, after {after / 1e6:.2f}); "
          f"ratio {rate / bare:.2f}; cpus {os.cpu_count()}, load {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
