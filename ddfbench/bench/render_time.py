"""Render-time benchmark, the DDF paper's Fig. 5 as a table and a plot: first vs later renders of
the same scene, per representation, against the full mesh's BVH measured in the same process.

    python -m ddfbench.bench.render_time                                  mesh LODs on the bunny, scene=depth
    python -m ddfbench.bench.render_time --scene paper_fig4 --size 128 --renders 8 --plot fig5.png
    python -m ddfbench.bench.render_time --model ddf=results/single/<key>/model.pt   a saved artifact of any family

Renders are interleaved (ddfbench.bench.timing.measure_side_by_side): each representation's first
render in turn, then rounds of one render each, the order rotated, so every row sees the same machine
load and the ratios between rows hold on a busy machine even where the seconds drift. The price: a
fast representation rendered right after a slow one starts with caches the slow one filled, so a
10 ms mesh frame beside a 20 s network frame reads a little slower than alone.

Columns: setup_s (build or load: mesh decimation + scene, or Family.load), render_1_s (the cold
render: lazy setup such as the BVH commit or weights to the device included), later_median_s and
later_iqr_s (renders 2..N), rays_per_s (primary + shadow + bounce rays of one render / later median),
field_evals (field evaluations of one render, as counted by the renderer: 0 for the mesh), vs_bvh
(the full mesh's later median / this one's: above 1 is faster than the BVH).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from ddfbench.bench.timing import measure_side_by_side
from ddfbench.core.clock import clock, compute_threads
from ddfbench.core.geometry import BOX_HALF
from ddfbench.core.plugins import CONF_DIR
from ddfbench.core.representation import Representation
from ddfbench.models import load_family
from ddfbench.render import mesh_reference
from ddfbench.render.integrator import render
from ddfbench.render.scene import parse_scene, plan_passes
from ddfbench.truth.shapes import load_shape


def _config(group: str, name: str) -> dict:
    with initialize_config_dir(config_dir=os.path.join(CONF_DIR, group), version_base="1.3"):
        return OmegaConf.to_container(compose(config_name=name), resolve=True)


def _rows(reps: list[tuple[str, float, Representation]], scene, renders: int) -> list[dict]:
    """A table row per (name, setup seconds, representation): `renders` renders each, interleaved (module
    docstring), the first cold, no untimed warm-up (seconds)."""
    passes = plan_passes(scene)
    fns = {name: (lambda rep=rep: render(rep, scene, passes, seed=0)) for name, _, rep in reps}
    timed = measure_side_by_side(fns, repeats=renders - 1, warmup=0)
    rows = []
    for name, setup_s, _ in reps:
        (_, counts), timing = timed[name]
        rays = counts["primary_rays"] + counts["shadow_rays"] + counts["bounce_rays"]
        rows.append({"name": name, "setup_s": setup_s, "render_1_s": timing.cold_s, "later_median_s": timing.median_s,
                     "later_iqr_s": timing.iqr_s, "rays": rays, "rays_per_s": rays / timing.median_s,
                     "field_evals": int(counts.get("field_evals", 0)), "seconds": [timing.cold_s, *timing.runs_s]})
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shape", default="bunny", help="a conf/shape preset")
    ap.add_argument("--scene", default="depth", help="a conf/scene preset")
    ap.add_argument("--size", type=int, default=128, help="image width and height")
    ap.add_argument("--renders", type=int, default=6, help="renders per representation (the first is cold)")
    ap.add_argument("--lods", default="10000,2000,500", help="mesh LOD face counts, comma-separated")
    ap.add_argument("--model", action="append", default=[], metavar="FAMILY=PATH", help="a saved artifact to load")
    ap.add_argument("--plot", help="write the per-render times as a PNG plot here")
    args = ap.parse_args(argv)
    if args.renders < 2:
        ap.error("--renders must be at least 2 (first and later renders)")

    shape = load_shape(_config("shape", args.shape))
    scene = parse_scene({**_config("scene", args.scene), "width": args.size, "height": args.size})
    models = [(family, path, f"{family} {os.path.join(*os.path.normpath(path).split(os.sep)[-2:])}")
              for family, _, path in (spec.partition("=") for spec in args.model)]
    if len({name for _, _, name in models}) < len(models):
        ap.error("--model: two artifacts share a family and a run folder name; give each its own folder")
    reps = []
    for faces in [0] + [int(f) for f in args.lods.split(",") if f.strip()]:
        start = time.perf_counter()
        rep = mesh_reference(shape.mesh, BOX_HALF, faces=faces)
        name = f"mesh faces={len(rep.mesh.faces)}"
        if name in {n for n, _, _ in reps}:  # a LOD at or above the mesh's face count is the mesh itself
            print(f"--lods {faces}: as many faces as an earlier row ({name}), so not rendered again", file=sys.stderr)
            continue
        reps.append((name, time.perf_counter() - start, rep))
    for family, path, name in models:
        start = clock()
        rep = load_family(family).load(path)
        reps.append((name, clock() - start, rep))
    rows = _rows(reps, scene, args.renders)

    bvh = rows[0]["later_median_s"]
    print(f"shape={args.shape} scene={args.scene} {args.size}x{args.size} cameras={len(scene.cameras)} "
          f"spp={scene.spp} renders={args.renders} threads={compute_threads()}")
    print("| representation | setup_s | render_1_s | later_median_s | later_iqr_s | rays | rays_per_s | field_evals | vs_bvh |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['name']} | {r['setup_s']:.4f} | {r['render_1_s']:.4f} | {r['later_median_s']:.4f} | "
              f"{r['later_iqr_s']:.4f} | {r['rays']} | {r['rays_per_s']:.3g} | {r['field_evals']} | "
              f"{bvh / r['later_median_s']:.2f} |")
    if args.plot:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(6, 4))
        for r in rows:
            ax.plot(range(1, args.renders + 1), r["seconds"], marker="o", label=r["name"])
        ax.set_xticks(range(1, args.renders + 1))
        ax.set(xlabel="render #", ylabel="seconds", yscale="log",
               title=f"{args.shape}, scene={args.scene}, {args.size}² px: first vs later renders")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(args.plot, dpi=120)
        print(f"plot: {args.plot}", file=sys.stderr)


if __name__ == "__main__":
    main()
