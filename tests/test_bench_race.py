"""The `race` section of `python -m ddfbench.bench` (DDF vs Warp BVH vs Embree vs sphere tracing) at tiny
sizes on the CPU: every contestant answers the same rays, Warp's depth equals the oracle's, the sweep and
the four capacities are all there. No timing assertions."""

import json
import math

import pytest

from ddfbench.bench.__main__ import main

pytest.importorskip("warp", reason='NVIDIA Warp not installed (pip install -e ".[gpu]")')


@pytest.fixture(scope="module")
def race(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    code = main(["--sizes", "small", "--only", "race", "--repeats", "1", "--warmup", "0", "--threads", "1",
                 "--out", str(out)])
    return code, json.loads((out / "bench-cpu-small.json").read_text())["sections"]["race"]


def test_race_runs_every_contestant_on_both_ray_sets(race):
    code, sec = race
    assert code == 0 and sec["error"] is None
    for set_name in ("primary", "incoherent"):
        d = sec["details"][set_name]
        for name in ("ddf_fp32", "ddf_bf16", "warp_bvh", "embree_all_cores", "neural_sdf_trace", "grid_sdf_trace"):
            assert d[name]["rays_per_s"] > 0 and 0.0 <= d[name]["mask_iou"] <= 1.0, (set_name, name)
        # the BVH answers the oracle's rays exactly (float32 casts of one mesh)
        assert d["warp_bvh"]["mask_iou"] == 1.0 and d["warp_bvh"]["depth_mae"] < 1e-5
        assert d["embree_all_cores"]["mask_iou"] == 1.0 and d["embree_all_cores"]["depth_mae"] == 0.0
        assert sec["details"]["embree_all_cores"].startswith("open3d") and sec["details"]["reference"] == "open3d oracle"
        for name in ("neural_sdf_device_fp32", "neural_sdf_device_bf16", "grid_sdf_device_fp32"):  # the resident tracer
            assert d[name]["rays_per_s"] > 0 and 0.0 <= d[name]["mask_iou"] <= 1.0, (set_name, name)
        # the grid traced on the device finds what the numpy loop finds on the same grid
        assert abs(d["grid_sdf_device_fp32"]["mask_iou"] - d["grid_sdf_trace"]["mask_iou"]) < 0.02
        assert d["fastest"]["ddf"] in ("ddf_fp32", "ddf_bf16") and d["fastest"]["grid_sdf"] == "grid_sdf_device_fp32"
        assert any(r["measure"].startswith(f"{set_name}: neural_sdf device tracer") and "numpy in and out" in r["reference"]
                   for r in sec["rows"])
        diff = d["ddf_bf16_vs_fp32_depth_diff"]
        assert math.isfinite(diff["depth_mae"]) and 0.0 <= diff["mask_disagreement"] <= 1.0
    assert all(math.isfinite(r["ratio"]) and r["ratio"] > 0 for r in sec["rows"])


def test_race_sweep_and_capacities(race):
    _, sec = race
    sweep = sec["details"]["sweep"]
    assert [r["rays"] for r in sweep] == [100, 400]
    assert "embree_all_cores" in sweep[0] and "embree_all_cores" not in sweep[1]  # embree_max = 100
    caps = sec["details"]["capacities"]
    assert list(caps) == ["c1", "c2", "c3", "c4"]
    assert [caps[c]["width"] for c in caps] == [64, 128, 256, 512]
    lods = [k for k in caps["c1"] if k.startswith("mesh_lod_")]
    assert len(lods) == 1 and int(lods[0].split("_")[-1]) <= 302  # the sizes' one LOD (300 triangles)
    for c in caps.values():  # the BVH and the LOD raced beside every capacity, scored like it
        assert c["warp_bvh"]["mask_iou"] == 1.0 and c["warp_bvh"]["depth_mae"] < 1e-5
        assert c[lods[0]]["depth_mae"] > 1e-4 and c["flops_per_ray"] > 2 * c["width"] ** 2 * (c["depth"] - 1)
    measures = [(r["measure"], r["reference"]) for r in sec["rows"] if r["measure"].startswith("capacity c3")]
    assert {ref for _, ref in measures} == {"same network fp32 rays/s", "warp_bvh (Warp) beside it rays/s",
                                            f"{lods[0]} (Warp) beside it rays/s"}
    assert {"ddf_load_or_fit_s", "warp_bvh_build_s"} <= set(sec["details"]["cold"])



def test_race_on_a_machine_without_open3d_or_pymeshlab(tmp_path):
    """A GPU machine gets only small wheels (no open3d, no pymeshlab): with --oracle-backend warp the race
    runs there, every contestant answers, and Embree on every core is embreex in one process per core."""
    import subprocess
    import sys

    script = ("import sys; sys.modules['open3d'] = None; sys.modules['pymeshlab'] = None\n"
              "from ddfbench.bench.__main__ import main\n"
              f"sys.exit(main(['--sizes', 'small', '--only', 'race', '--repeats', '1', '--warmup', '0', '--threads', '1',"
              f" '--oracle-backend', 'warp', '--out', {str(tmp_path)!r}]))\n")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    doc = json.loads((tmp_path / "bench-cpu-small.json").read_text())
    sec = doc["sections"]["race"]
    assert sec["error"] is None and doc["options"]["oracle_backend"] == "warp"
    assert doc["env"]["versions"]["open3d"] is None and doc["env"]["versions"]["warp"]  # blocked counts as absent
    assert sec["details"]["embree_all_cores"].startswith("embreex in ")
    assert sec["details"]["reference"] == "embreex pool"  # Warp is scored against Embree, not against itself
    for set_name in ("primary", "incoherent"):
        d = sec["details"][set_name]
        assert d["warp_bvh"]["mask_iou"] == 1.0 and d["warp_bvh"]["depth_mae"] < 1e-5
        assert d["embree_all_cores"]["mask_iou"] == 1.0 and d["embree_all_cores"]["depth_mae"] == 0.0
        for name in ("ddf_fp32", "ddf_bf16", "neural_sdf_trace", "grid_sdf_trace"):
            assert d[name]["rays_per_s"] > 0 and 0.0 <= d[name]["mask_iou"] <= 1.0, (set_name, name)
    assert "embree_all_cores" in sec["details"]["sweep"][0]


def test_a_short_race_leaves_out_embree_the_loops_and_the_eager_tracers(tmp_path):
    """embree=false, sdf_loops=false, sdf_eager=false (the repeats' later processes): no Embree pool is started
    or timed, the reference is the oracle's, and only the device tracers that remain race (on the CPU: the grid's);
    capacity_levels races the chosen capacities alone."""
    sets = ["race.embree=false", "race.sdf_loops=false", "race.sdf_eager=false", "race.capacity_levels=[c1]", "race.lods=[]"]
    code = main(["--sizes", "small", "--only", "race", "--repeats", "1", "--warmup", "0", "--threads", "1",
                 "--out", str(tmp_path), *[a for s in sets for a in ("--set", s)]])
    doc = json.loads(next(tmp_path.glob("bench-cpu-small*.json")).read_text())
    det = doc["sections"]["race"]["details"]
    assert code == 0 and det["embree_all_cores"].startswith("not run: embree=false")
    assert det["reference"] == "open3d oracle" and "embree_pool_start_s" not in det["cold"]
    assert list(det["capacities"]) == ["c1"]  # the chosen level alone
    for set_name in ("primary", "incoherent"):
        raced = {k for k, v in det[set_name].items() if isinstance(v, dict) and "rays_per_s" in v}
        assert not raced & {"embree_all_cores", "neural_sdf_trace", "grid_sdf_trace", "neural_sdf_device_fp32"}
        assert {"grid_sdf_device_fp32", "warp_bvh", "ddf_fp32"} <= raced
        assert det[set_name]["fastest"]["grid_sdf"] == "grid_sdf_device_fp32" and "neural_sdf" not in det[set_name]["fastest"]


def test_a_race_without_its_main_part_races_only_the_capacities(tmp_path):
    """main=false (issue 51's capacity repeats): no SDF is made and neither ray set nor the sweep is raced; the chosen
    capacity races beside the BVH on the seed's primary rays, and bench.repeats pools such runs."""
    from ddfbench.bench import repeats

    sets = ["race.main=false", "race.embree=false", "race.capacity_levels=[c2]", "race.lods=[]"]
    for seed in (1, 2):
        code = main(["--sizes", "small", "--only", "race", "--repeats", "1", "--warmup", "0", "--threads", "1",
                     "--out", str(tmp_path / f"s{seed}"), "--set", f"race.ray_seed={seed}",
                     *[a for s in sets for a in ("--set", s)]])
        assert code == 0
    paths = [str(next((tmp_path / f"s{seed}").glob("bench-cpu-small*.json"))) for seed in (1, 2)]
    det = json.loads(open(paths[0]).read())["sections"]["race"]["details"]
    assert not {"primary", "incoherent", "sweep", "neural_sdf", "grid_sdf"} & set(det)
    assert list(det["capacities"]) == ["c2"] and det["capacities"]["c2"]["warp_bvh"]["mask_iou"] == 1.0
    assert det["capacities"]["c2"]["ddf_fp32"]["rays_per_s"] > 0
    rows = {r["quantity"]: r for r in repeats.pool([repeats.load_race(p) for p in paths])}
    assert rows["capacity c2 (128x4): DDF / warp_bvh"]["n"] == 2
    assert not any(q.startswith(("primary", "incoherent")) for q in rows)
