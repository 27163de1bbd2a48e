"""Section 12 of the bench: meshes of a given triangle count, the log-log crossover, and a small run."""

import importlib.util
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from ddfbench.bench.context import Context
from ddfbench.bench.crossover import crossover, depth_error, mesh_with_faces, run
from ddfbench.bench.sizes import SIZES
from ddfbench.bench.views import incoherent_rays
from ddfbench.truth.oracle import Oracle


def test_subdivided_meshes_keep_the_surface_and_decimated_ones_shrink(sphere):
    base = sphere.mesh
    bigger = mesh_with_faces(base, 4 * len(base.faces) + 1)
    assert len(bigger.faces) == 16 * len(base.faces)  # two midpoint passes
    assert bigger.area == pytest.approx(base.area, rel=1e-9)  # midpoints of flat triangles: the same surface
    rng = np.random.default_rng(0)
    o = rng.uniform(-0.3, 0.3, (500, 3)) * [1, 1, 0] + [0, 0, -0.6]
    d = np.tile([0.0, 0.0, 1.0], (500, 1))
    t_base, t_big = Oracle(base).hit_distance(o, d), Oracle(bigger).hit_distance(o, d)
    np.testing.assert_allclose(t_big, t_base, atol=1e-5)
    smaller = mesh_with_faces(base, len(base.faces) // 4)
    assert len(smaller.faces) <= len(base.faces) // 4 + 2


def test_the_crossover_is_interpolated_log_log_between_the_bracketing_counts():
    # ratio 2 at 1e3, 0.5 at 1e5: log ratio falls linearly in log count, 1 halfway: 1e4
    assert crossover([1e2, 1e3, 1e5], [4.0, 2.0, 0.5]) == pytest.approx(1e4)
    assert crossover([1e3, 1e5], [0.5, 2.0]) == pytest.approx(1e4)  # rising works the same
    assert crossover([1e3, 1e4], [2.0, 3.0]) is None
    assert crossover([1e3, 1e4], [1.0, 3.0]) == pytest.approx(1e3)


def test_depth_error_counts_only_rays_both_hit():
    t = np.array([1.0, 2.0, np.inf, 4.0])
    ref = np.array([1.5, 2.0, 3.0, np.inf])
    err = depth_error(t, ref)
    assert err["depth_mae"] == pytest.approx(0.25) and err["hit_flip_share"] == pytest.approx(0.5)


def test_a_small_run_gives_a_row_per_count_model_and_ray_set(tmp_path):
    sizes = SIZES["small"]["crossover"]
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # as the bench's --threads 1 sets it
    try:
        res = run(Context("cpu", sizes, repeats=1, warmup=0, workdir=str(tmp_path), threads=1))
    finally:
        torch.set_num_threads(threads)
    counts = res.details["counts"]
    assert len(counts) == len(sizes["counts"]) and counts == sorted(counts)
    assert len(res.rows) == len(counts) * len(sizes["models"]) * 2
    assert all(r.ratio > 0 and math.isfinite(r.ratio) for r in res.rows)
    for kind in ("primary", "incoherent"):
        entries = res.details[kind]
        # open3d's BVH casts on every core, the DDF on torch's threads: each figure names its own
        assert all(e["bvh"]["threads"] == os.cpu_count() for e in entries)
        assert all(e[name]["threads"] == 1 for e in entries for name in sizes["models"])
        subdivided = [e for e in entries if e["faces"] > res.details["shape_faces"]]
        assert subdivided and all(e["depth_mae"] < 1e-5 and e["hit_flip_share"] < 0.01 for e in subdivided)
        for name in sizes["models"]:
            found = res.details["crossover"][f"{name}, {kind}"]
            assert len(found["bvh_over_ddf"]) == len(counts)


# the one kernel is Triton's: without it (a CPU build of torch; the README's `pip install triton==3.6.0` adds it)
# the fused path says so and is not checked here
NO_TRITON = pytest.mark.skipif(importlib.util.find_spec("triton") is None,
                               reason="Triton is not installed (it comes with CUDA builds of torch)")


def test_the_cpu_path_is_the_fp32_depth():
    from ddfbench.bench.crossover import ddf_depth
    from ddfbench.bench.ddf import make_ddf

    depth, variant = ddf_depth(make_ddf({}, "cpu", "ddf_tuned"), "cpu")  # the CPU: fp32, no kernel asked for
    assert variant == "DDFDepth fp32" and depth.precision == "fp32" and depth.chunk == 1 << 21


@NO_TRITON
def test_the_device_path_names_its_variant_and_the_line_grid_falls_back_to_bf16():
    from ddfbench.bench.crossover import ddf_depth
    from ddfbench.bench.ddf import make_ddf

    grid = make_ddf({}, "cpu", "ddf_line_grid_tuned")
    depth, variant = ddf_depth(grid, "cpu", fused=True)  # asked for the one kernel: the line grid does not fit it
    assert depth.precision == "bf16" and "not run" in variant and "line grid" in variant
    o, d = (torch.as_tensor(a) for a in incoherent_rays(300, seed=3))
    t = depth(o, d)
    assert t.shape == (300,) and t.dtype == torch.float32


@NO_TRITON
def test_the_one_kernel_depth_is_checked_and_named_where_triton_runs(tmp_path):
    """The fused path as on CUDA, here under Triton's CPU interpreter (set before Triton is imported: a fresh
    process): the one-kernel depth of ddf_tuned passes the check against bf16 and is the variant."""
    script = ("from ddfbench.bench.crossover import ddf_depth\nfrom ddfbench.bench.ddf import make_ddf\n"
              "depth, variant = ddf_depth(make_ddf({}, 'cpu', 'ddf_tuned'), 'cpu', fused=True)\n"
              "print(variant); print(type(depth._step).__name__)\n")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "TRITON_INTERPRET": "1"})
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.splitlines()[-2:] == ["DDFDepth bf16 fused depth (one kernel)", "FusedDepth"]


def _bench(args: list[str], out, script_prefix: str | None = None) -> dict:
    """Section crossover through `python -m ddfbench.bench` (small sizes, one repeat, one thread), in this
    process or, with script_prefix, in a fresh one that runs script_prefix first; the report's JSON."""
    argv = ["--sizes", "small", "--only", "crossover", "--repeats", "1", "--warmup", "0", "--threads", "1",
            *args, "--out", str(out)]
    if script_prefix is None:
        from ddfbench.bench.__main__ import main

        threads = torch.get_num_threads()
        try:
            assert main(argv) == 0
        finally:
            torch.set_num_threads(threads)  # main sets it for the process
    else:
        script = f"{script_prefix}\nfrom ddfbench.bench.__main__ import main\nsys.exit(main({argv!r}))\n"
        proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr[-3000:]
    (report,) = out.glob("*.json")
    return json.loads(report.read_text())


def test_warp_backend_on_prepared_meshes_and_on_a_machine_without_pymeshlab(tmp_path, sphere):
    """--oracle-backend warp: Warp's BVH and the DDF's device path; the meshes go to the prepared folder, and a
    process without pymeshlab (or open3d: a lent GPU) loads them and measures the same meshes."""
    own = len(sphere.mesh.faces)  # 5120: the shape's own count, between a decimated and a subdivided one
    counts = [500, own, 4 * own]
    folder = tmp_path / "prepared"
    args = ["--oracle-backend", "warp", "--set", f"crossover.counts={counts}", "--set", f"crossover.prepared={folder}"]
    doc = _bench(args, tmp_path / "here")
    sec = doc["sections"]["crossover"]
    assert sec["error"] is None and doc["options"]["oracle_backend"] == "warp"
    det = sec["details"]
    assert det["bvh"] == "Warp BVH (cpu)" and det["models"]["ddf_tuned"]["variant"] == "DDFDepth fp32"
    assert det["counts"][1:] == [own, 4 * own] and det["counts"][0] <= 502
    assert len(det["bvh_build_s"]) == 3 and all(b > 0 for b in det["bvh_build_s"])
    assert len(sec["rows"]) == 3 * 2 and all("Warp BVH (cpu)" in r["reference"] for r in sec["rows"])
    assert all(r["ratio"] > 0 and math.isfinite(r["ratio"]) for r in sec["rows"])
    assert any("Warp BVH" in note and "DDFDepth fp32" in note for note in sec["notes"])
    for kind in ("primary", "incoherent"):
        lod, same, finer = det[kind]
        assert same["depth_mae"] == 0 and same["hit_flip_share"] == 0  # the truth: this backend, this very mesh
        assert finer["depth_mae"] < 1e-5 and finer["hit_flip_share"] < 0.01  # subdivided: the same surface
        assert lod["depth_mae"] > 1e-4  # the 500-triangle LOD is a coarser surface than the truth's
    saved = sorted(folder.glob("*.npz"))  # only the decimated mesh: subdividing needs no pymeshlab
    assert len(saved) == 1 and saved[0].name.startswith("sphere-lod-")

    script = "import sys; sys.modules['open3d'] = None; sys.modules['pymeshlab'] = None"
    again = _bench(args, tmp_path / "there", script)  # cannot decimate: only the saved LODs let it run
    sec2 = again["sections"]["crossover"]
    assert sec2["error"] is None and again["env"]["versions"]["open3d"] is None
    assert sec2["details"]["counts"] == det["counts"]
    for kind in ("primary", "incoherent"):  # the same meshes, the same rays, the same deterministic BVH
        assert [e["depth_mae"] for e in sec2["details"][kind]] == [e["depth_mae"] for e in det[kind]]
    assert sorted(folder.glob("*.npz")) == saved
