"""`python -m ddfbench.bench`: ddfbench's own speed, every figure beside a reference measured in the
same process (DESIGN.md, timing rules). One module per section:

1. sampling     surface-sampling labels/s vs bare open3d cast_rays rays/s
2. oracle       first-hit rays/s per backend (open3d, embreex), primary and incoherent rays
3. ddf          DDF ray answering vs the bare network forward (+ backward), and vs Embree
4. tracing      sphere tracer vs the naive all-rays loop: evaluations per pixel and time
5. grid         level-set grid SDF build vs brute force: time and error
6. metrics      chamfer + f-score + sided distance vs the bare KD-tree work
7. training     samples/s per learned family vs a bare training step of its network
8. end_to_end   the default run and the smoke sweep, wall time per stage
9. race         DDF (fp32, bf16, compiled) vs Warp BVH vs Embree on all cores vs sphere tracing, same rays,
                each with its accuracy; ray-count sweep; the four DDF capacities (run by default on CUDA only)
10. field_cost  points/s of the GAN-SDF generator per eval chunk vs the neural SDF's field, and each
                network's GFLOP/s vs a dense matrix product
11. gan_train   the thesis GAN's G+D forward and backward with the family's max pools vs torch's MaxPool1d
12. crossover   a BVH's time per ray from ~1k to ~4M triangles (the shape decimated and subdivided) against the
                DDF presets' on the same rays, the count where they meet, each LOD's depth error

Each section module has `run(ctx: Context) -> SectionResult`; timing.py measures, results.py holds
the rows, sizes.py the problem sizes, table.py writes the outputs.
"""

SECTIONS = ("sampling", "oracle", "ddf", "tracing", "grid", "metrics", "training", "end_to_end", "race", "field_cost",
            "gan_train", "crossover")
CUDA_ONLY_BY_DEFAULT = ("race",)  # left out of a --device cpu run unless --only names it
ON_REQUEST = ("crossover",)  # long (minutes): run only when --only names it
