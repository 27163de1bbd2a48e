"""Suite v1's erratum measured: open3d's BVH casting the bunny's 128² frame pair (render_shapes' two cameras) on
every core (its default, what the mesh family did) against one thread, side by side in one process
(ddfbench.bench.timing), in rounds.

    python tools/bvh_threads.py --out reports/bench/bvh_threads      (writes bvh_threads.json and bvh_threads.md)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics

import numpy as np
import open3d as o3d

from ddfbench.bench.timing import measure_side_by_side
from ddfbench.render.camera import orbit_cameras
from ddfbench.truth.oracle import open3d_scene
from ddfbench.truth.shapes import load_shape


def rays(size: int = 128) -> np.ndarray:
    """(2·size², 6) float32 pixel-centre rays of the scene presets' two orbit cameras (conf/scene/depth.yaml)."""
    cameras = orbit_cameras(2, 2.0, 25.0, 30.0, 40.0, size, size)
    return np.concatenate([np.concatenate(c.rays(), axis=1) for c in cameras]).astype(np.float32)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", required=True)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    mesh = load_shape({"name": "bunny"}).mesh
    scene = open3d_scene(mesh)  # as the oracle builds it
    runs, batch = [], o3d.core.Tensor(rays())
    for round_ in range(args.rounds):
        found = measure_side_by_side({"every core": lambda: scene.cast_rays(batch),
                                      "one thread": lambda: scene.cast_rays(batch, nthreads=1)}, args.repeats)
        every, one = found["every core"][1], found["one thread"][1]
        runs.append({"round": round_, "every_core_s": every.median_s, "every_core_iqr_s": every.iqr_s,
                     "one_thread_s": one.median_s, "one_thread_iqr_s": one.iqr_s,
                     "ratio": one.median_s / every.median_s})
    ratios = [r["ratio"] for r in runs]
    doc = {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(), "rays": 2 * 128 * 128,
           "repeats": args.repeats, "runs": runs, "ratio_median": statistics.median(ratios),
           "ratio_min": min(ratios), "ratio_max": max(ratios)}
    os.makedirs(args.out, exist_ok=True)
    with open(os.path.join(args.out, "bvh_threads.json"), "w") as fh:
        json.dump(doc, fh, indent=1)
    lines = ["| round | every core s (IQR) | one thread s (IQR) | one thread / every core |", "|---|---|---|---|"]
    lines += [f"| {r['round']} | {r['every_core_s']:.3g} ({r['every_core_iqr_s']:.2g}) | {r['one_thread_s']:.3g} "
              f"({r['one_thread_iqr_s']:.2g}) | {r['ratio']:.3g} |" for r in runs]
    lines += ["", f"Median ratio {doc['ratio_median']:.3g} (range {doc['ratio_min']:.3g}–{doc['ratio_max']:.3g}) over "
              f"{len(runs)} rounds; {doc['cores']} cores, {args.repeats} interleaved calls a figure."]
    with open(os.path.join(args.out, "bvh_threads.md"), "w") as fh:
        fh.write("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
