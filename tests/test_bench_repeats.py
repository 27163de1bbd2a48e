"""ddfbench.bench.repeats: ratios are formed inside each run, pooled across runs with the t interval, the
capacity verdict picks the most accurate capacity whose interval lies above 1, and bad input is one line."""

import json
import math

import pytest

from ddfbench.bench import repeats
from ddfbench.bench.views import EYE, orbit_eye


def _set(ddf_rate: float, warp_rate: float) -> dict:
    def c(rate, mae=1e-2, iou=0.9):
        return {"rays_per_s": rate, "depth_mae": mae, "mask_iou": iou, "cold_s": 0.5}
    return {"fastest": {"ddf": "ddf_bf16_fused_depth", "neural_sdf": "neural_sdf_device_tf32",
                        "grid_sdf": "grid_sdf_device_fp32"},
            "ddf_bf16_fused_depth": c(ddf_rate), "warp_bvh": c(warp_rate, 1e-7, 1.0),
            "neural_sdf_device_tf32": c(ddf_rate / 50), "grid_sdf_device_fp32": c(ddf_rate / 20),
            "neural_sdf_trace": c(ddf_rate / 500), "grid_sdf_trace": c(ddf_rate / 100),
            "ddf_bare_bf16": c(ddf_rate / 4)}


def _cap(ddf_rate, warp_rate, mae, lod_rate=None):
    out = {"width": 64, "depth": 3, "fastest": "ddf_bf16", "ddf_bf16": {"rays_per_s": ddf_rate, "depth_mae": mae,
                                                                         "mask_iou": 0.8},
           "warp_bvh": {"rays_per_s": warp_rate, "depth_mae": 0.0, "mask_iou": 1.0}}
    if lod_rate:
        out["mesh_lod_1000"] = {"rays_per_s": lod_rate, "depth_mae": 3e-3, "mask_iou": 0.99}
    return out


def _run(seed: int, ratio: float) -> dict:
    return {"ray_seed": seed, "primary": _set(2e9 * ratio, 2e9), "incoherent": _set(1e9, 1e9 / ratio),
            "capacities": {"c1": _cap(3e9, 1e9 * (1 + 0.01 * seed), 2e-2, 6e9),
                           "c2": _cap(2e9, 1e9 * (1 + 0.01 * seed), 1e-2, 6e9),
                           "c3": _cap(0.5e9, 1e9, 5e-3, 6e9)},
            "cold": {"warp_bvh_build_s": 0.01 * seed}}


def test_ratios_are_formed_inside_a_run():
    r = repeats.ratios(_run(1, 2.0))
    assert r["primary: DDF / warp_bvh"] == pytest.approx(2.0)
    assert r["incoherent: DDF / warp_bvh"] == pytest.approx(2.0)
    assert r["primary: DDF / neural SDF device tracer"] == pytest.approx(50.0)
    assert r["primary: neural SDF device tracer / neural_sdf_trace"] == pytest.approx(10.0)
    assert r["primary: DDF / its bare forward"] == pytest.approx(4.0)
    assert r["capacity c1 (64x3): DDF / mesh_lod_1000"] == pytest.approx(0.5)
    assert r["cold: warp_bvh_build_s"] == pytest.approx(0.01)


def test_pooling_gives_median_and_the_t_interval_by_hand():
    rows = {r["quantity"]: r for r in repeats.pool([_run(1, 1.0), _run(2, 2.0), _run(3, 3.0)])}
    row = rows["primary: DDF / warp_bvh"]
    half = 4.302652729911275 * 1.0 / math.sqrt(3)  # t(0.975, 2) * std / sqrt(n), std of 1, 2, 3 = 1
    assert row["n"] == 3 and row["median"] == pytest.approx(2.0) and row["std"] == pytest.approx(1.0)
    assert (row["lo"], row["hi"]) == (0.0, pytest.approx(2.0 + half))  # 2 - half < 0: cut at 0 (a ratio)
    assert row["values"] == {"1": pytest.approx(1.0), "2": pytest.approx(2.0), "3": pytest.approx(3.0)}


def test_the_verdict_names_the_most_accurate_capacity_faster_than_the_bvh():
    rows = repeats.pool([_run(k, 2.0) for k in (1, 2, 3)])
    lines = repeats.verdicts(rows)
    assert lines[0] == "Capacities measured in two runs or more: capacity c1 (64x3), capacity c2 (64x3), capacity c3 (64x3)."
    assert "c2" in lines[1] and "c3" not in lines[1]  # c3 is more accurate but slower than the BVH
    assert any("mesh_lod_1000" in line and "0.3x the DDF's" in line for line in lines)


def test_no_capacity_faster_is_said(tmp_path):
    run = _run(1, 1.0)
    for cap in run["capacities"].values():
        cap["ddf_bf16"]["rays_per_s"] = 1e8
    assert repeats.verdicts(repeats.pool([run, {**run, "ray_seed": 2}]))[1].startswith("No DDF capacity")


def _write(path, details, error=None):
    path.write_text(json.dumps({"env": {"gpu": "X", "git_sha": "abc"},
                                "sections": {"race": {"error": error, "details": details}}}))
    return str(path)


def test_main_writes_the_pooled_table_and_refuses_bad_input(tmp_path, capsys):
    paths = [_write(tmp_path / f"r{k}.json", _run(k, 1.5 + 0.1 * k)) for k in (1, 2, 3)]
    assert repeats.main([*paths, "--out", str(tmp_path / "out")]) == 0
    md = (tmp_path / "out" / "repeats.md").read_text()
    assert "ray seeds 1, 2, 3" in md and "| primary: DDF / warp_bvh | 3 |" in md
    assert repeats.main([paths[0], paths[0]]) == 2
    assert "each run needs its own" in capsys.readouterr().err
    bad = _write(tmp_path / "bad.json", {}, error="RuntimeError: CUDA error")
    assert repeats.main([bad]) == 2 and "bad.json: its race failed" in capsys.readouterr().err
    (tmp_path / "cut.json").write_text("{")
    assert repeats.main([str(tmp_path / "cut.json")]) == 2 and "cut.json: not a bench JSON" in capsys.readouterr().err


def test_ray_seeds_turn_the_camera_about_the_vertical_axis():
    assert orbit_eye(1) == pytest.approx(EYE) and orbit_eye(6) == pytest.approx(EYE)
    for k in (2, 3, 4, 5):
        e = orbit_eye(k)
        assert e[1] == pytest.approx(EYE[1]) and math.hypot(e[0], e[2]) == pytest.approx(math.hypot(EYE[0], EYE[2]))
        assert not e == pytest.approx(EYE)


def test_a_stopped_run_pools_what_it_measured(tmp_path):
    """A race stopped by its time limit before the capacities still adds its ray-set ratios; a quantity only one
    run has gets no interval, and the capacity verdict reads only capacities measured twice or more."""
    cut = {k: v for k, v in _run(3, 3.0).items() if k != "capacities"}
    paths = [_write(tmp_path / "r1.json", _run(1, 1.0)), _write(tmp_path / "r2.json", _run(2, 2.0)),
             _write(tmp_path / "r3.json", cut, error="Stopped: SIGTERM: the bench was stopped midway")]
    runs = [repeats.load_race(p) for p in paths]
    rows = {r["quantity"]: r for r in repeats.pool(runs)}
    assert rows["primary: DDF / warp_bvh"]["n"] == 3 and rows["primary: DDF / warp_bvh"]["median"] == pytest.approx(2.0)
    assert rows["capacity c1 (64x3): DDF / warp_bvh"]["n"] == 2
    assert "time limits, pooling what they measured before: seeds 3." in repeats.to_markdown(runs, list(rows.values()), paths)
    only_one = repeats.pool([runs[0], {**runs[2], "ray_seed": 4}])  # a capacity measured once: n 1, no interval
    caps = [r for r in only_one if r["quantity"].startswith("capacity")]
    assert caps and all(r["n"] == 1 and math.isnan(r["lo"]) for r in caps)
    assert repeats.verdicts(only_one)[0] == "Capacities measured in two runs or more: none."


def test_capacity_variants_are_named_when_the_first_run_has_none_and_ratios_pool_geometrically():
    first = {k: v for k, v in _run(1, 1.0).items() if k != "capacities"}
    names = repeats.fastest_names([first, _run(2, 2.0), _run(3, 2.0)])
    assert names["capacity c1"] == ["ddf_bf16", "ddf_bf16"]
    row = {r["quantity"]: r for r in repeats.pool([_run(1, 1.0), _run(2, 4.0)])}["primary: DDF / warp_bvh"]
    assert row["gmean"] == pytest.approx(2.0) and row["glo"] < 2.0 < row["ghi"]  # sqrt(1 * 4)
    cold = {r["quantity"]: r for r in repeats.pool([_run(1, 1.0), _run(2, 4.0)])}["cold: warp_bvh_build_s"]
    assert math.isnan(cold["lo"]) and cold["median"] == pytest.approx(0.015)  # first launch and relaunch mixed


def test_runs_of_different_networks_are_not_pooled(tmp_path, capsys):
    a, b = _run(1, 1.0), _run(2, 1.0)
    a["ddf"], b["ddf"] = {"prepared": "ddf_tuned-128x4-aaaa"}, {"prepared": "ddf_tuned-128x4-bbbb"}
    paths = [_write(tmp_path / "a.json", a), _write(tmp_path / "b.json", b)]
    assert repeats.main(paths) == 2 and "raced different ddf networks" in capsys.readouterr().err
    a["ddf"] = b["ddf"]  # the same main DDF, but capacity c3 fit twice (a run stopped before c4 still pools)
    a["capacities"] = {"c3": {"prepared": "ddf_tuned-256x6-aaaa"}, "c4": {"prepared": "ddf_tuned-512x6-cccc"}}
    b["capacities"] = {"c3": {"prepared": "ddf_tuned-256x6-bbbb"}}
    paths = [_write(tmp_path / "a.json", a), _write(tmp_path / "b.json", b)]
    assert repeats.main(paths) == 2 and "raced different capacity c3 networks" in capsys.readouterr().err
    b["capacities"]["c3"] = a["capacities"]["c3"]
    paths = [_write(tmp_path / "a.json", a), _write(tmp_path / "b.json", b)]
    assert repeats.main(paths) == 0


@pytest.mark.parametrize("run", ["h200", "h200_capacities"])
def test_the_committed_gpu_repeats_regenerate_from_their_runs(tmp_path, run):
    """reports/bench/cuda/<run>/repeats.{md,json} are what `python -m ddfbench.bench.repeats` makes of the committed
    seed*.json beside them, byte for byte (a hand-edited figure fails here)."""
    import os

    folder = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "reports", "bench", "cuda", run)
    runs = json.load(open(os.path.join(folder, "repeats.json")))["runs"]
    cwd = os.getcwd()
    try:
        os.chdir(folder)  # the committed table names the runs as given on the command line
        assert repeats.main([*runs, "--out", str(tmp_path)]) == 0
    finally:
        os.chdir(cwd)
    for name in ("repeats.md", "repeats.json"):
        assert (tmp_path / name).read_bytes() == open(os.path.join(folder, name), "rb").read(), name
