"""Make the race's prepared folder on a CPU (issue 51): the DDF's four Pareto capacities, the neural and grid SDF and
the bunny's LODs, each fit for fixed steps and saved under the names a device's race loads (ddfbench.bench.prepared),
so a lent GPU spends no time fitting and needs no pymeshlab.

usage: python tools/device/make_prepared.py DIR [--only c1,c2,c3,c4,sdf,lods] [--steps 6600]
Two processes share 2 cores well: `--only c4` (the largest, ~12 minutes on one thread) beside the rest.
"""

from __future__ import annotations

import argparse

import torch

from ddfbench.bench.contestants import pareto_ddf_capacities, prepared_lod, sdf_contestants, surface_labels, train_ddf
from ddfbench.bench.context import Context
from ddfbench.bench.sizes import SIZES


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("folder")
    parser.add_argument("--only", default="c1,c2,c3,c4,sdf,lods", help="parts to make (comma-separated)")
    parser.add_argument("--steps", type=int, default=6600, help="fit steps of every network (race.fit_steps)")
    args = parser.parse_args()
    parts = args.only.split(",")
    unknown = set(parts) - {*pareto_ddf_capacities(), "sdf", "lods"}
    if unknown:
        parser.error(f"--only {args.only}: unknown part(s) {', '.join(sorted(unknown))} (c1, c2, c3, c4, sdf, lods)")
    torch.set_num_threads(1)
    sizes = {**SIZES["default"]["race"], "prepared": args.folder, "fit_steps": args.steps}
    ctx = Context(device="cpu", sizes=sizes, repeats=1, warmup=0, workdir=args.folder, threads=1)
    shape, samples = ctx.shape(sizes["shape"]), surface_labels(ctx)  # the race's labels
    for level, overrides in pareto_ddf_capacities().items():
        if level in parts:
            print(level, train_ddf(ctx, samples, overrides)[1], flush=True)
    if "lods" in parts:
        for faces in sizes["lods"]:
            lod = prepared_lod(sizes, shape.mesh, faces)
            print("lod", faces, len(lod.faces), flush=True)
    if "sdf" in parts:
        _, neural, _, grid = sdf_contestants(ctx)
        print("neural_sdf", neural, "\ngrid_sdf", grid, flush=True)


if __name__ == "__main__":
    main()
