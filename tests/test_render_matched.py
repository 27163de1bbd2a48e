"""Render speed at matched accuracy (ddfbench.report.matched) on synthetic records, and the experiment grid."""

import math

import pytest

from ddfbench.report import matched


def rec(model, family, depth_mae, warm_s, seed=0, trace=None, width=64, mask_iou=None):
    """A render record; an SDF preset carries its whole tracer in its config (as grid_sdf's does), a swept setting
    is its `++model.trace.*` overrides."""
    preset_trace = {"eps": 1e-5, "eps_abs": 1e-6, "omega": 1.0, "max_steps": 256} if "sdf" in family else {}
    model_cfg = {"family": family, **({"trace": {**preset_trace, **(trace or {})}} if preset_trace else {})}
    cfg = {"seed": seed, "model": model_cfg}
    return {"status": "ok", "schema_version": 1, "model": model, "family": family, "shape": {"name": "bunny"},
            "scene": {"width": width, "height": width}, "config": cfg,
            "overrides": [f"seed={seed}", *(f"++model.trace.{k}={v}" for k, v in (trace or {}).items())],
            "metrics": {"depth_mae": depth_mae, "mask_iou": mask_iou}, "cost": {"render_warm_s": warm_s}}


def records(sdf_loose_error):
    out = []
    for seed in (0, 1, 2):
        out.append(rec(matched.REFERENCE, "ddf", 2e-3, 0.1, seed))
        out.append(rec("ddf_paper", "ddf", 9e-3, 0.3, seed))  # another DDF preset: not a candidate
        out.append(rec("neural_sdf", "neural_sdf", 1e-3, 0.5, seed))  # default tracer
        out.append(rec("neural_sdf", "neural_sdf", 1.8e-3, 0.2, seed, {"eps_abs": 1e-3}))
        out.append(rec("neural_sdf", "neural_sdf", sdf_loose_error, 0.05, seed, {"eps_abs": 1e-2, "omega": 1.6}))
        out.append(rec("mesh", "mesh", 0.5e-3, 0.3, seed))
        out.append(rec("mesh_lod500", "mesh", 3e-3, 0.02, seed))
    return out


def by_family(df):
    return {r["family"]: r for _, r in df.iterrows()}


def test_matched_setting_is_the_fastest_at_most_as_inaccurate_as_the_ddf():
    rows = by_family(matched.matched_table(records(sdf_loose_error=5e-3)))
    assert set(rows) == {"neural_sdf", "mesh"}
    sdf = rows["neural_sdf"]
    assert sdf["default_setting"] == "neural_sdf" and sdf["default_speedup"] == pytest.approx(5.0)
    assert sdf["matched_setting"] == 'neural_sdf {"eps_abs": 0.001}' and sdf["matched_speedup"] == pytest.approx(2.0)
    assert rows["mesh"]["matched_setting"] == "mesh" and rows["mesh"]["matched_speedup"] == pytest.approx(3.0)
    assert sdf["reference_n"] == 3 and sdf["matched_n"] == 3


def test_a_looser_tracer_that_reaches_the_ddf_error_becomes_the_match():
    sdf = by_family(matched.matched_table(records(sdf_loose_error=1.9e-3)))["neural_sdf"]
    assert sdf["matched_setting"].startswith('neural_sdf {"eps_abs": 0.01') and sdf["matched_speedup"] == pytest.approx(0.5)


def test_a_setting_that_loses_the_silhouette_is_no_match():
    def with_iou(r):  # the loose tracer meets the DDF's depth error on the pixels both hit, but misses the edges
        loose = "omega" in "".join(r["overrides"])
        return {**r, "metrics": {**r["metrics"], "mask_iou": 0.80 if loose else 0.95 if r["family"] == "ddf" else 0.99}}

    sdf = by_family(matched.matched_table([with_iou(r) for r in records(sdf_loose_error=1.9e-3)]))["neural_sdf"]
    assert sdf["matched_setting"] == 'neural_sdf {"eps_abs": 0.001}' and sdf["matched_mask_iou"] == pytest.approx(0.99)
    assert sdf["reference_mask_iou"] == pytest.approx(0.95)


def test_no_setting_as_accurate_is_not_reached():
    recs = [r for r in records(5e-3) if r["model"] != "mesh"]  # only the coarse LOD is left
    rows = by_family(matched.matched_table(recs))
    assert not rows["mesh"]["matched_reached"] and rows["mesh"]["matched_setting"] == "mesh_lod500"
    assert math.isnan(rows["mesh"]["default_speedup"])  # the full mesh was not run
    assert matched.NOT_REACHED in matched.to_markdown(matched.matched_table(recs))


def test_a_tuned_preset_with_its_tracer_untouched_is_its_familys_default():
    recs = [{**r, "model": "neural_sdf_tuned"} if r["model"] == "neural_sdf" else r for r in records(5e-3)]
    sdf = by_family(matched.matched_table(recs))["neural_sdf"]
    assert sdf["default_setting"] == "neural_sdf_tuned" and sdf["default_speedup"] == pytest.approx(5.0)


def test_sizes_are_compared_only_with_their_own_size():
    recs = records(5e-3) + [rec("neural_sdf", "neural_sdf", 1e-4, 0.01, 0, width=32)]  # no 32x32 DDF
    df = matched.matched_table(recs)
    assert set(df["size"]) == {"64x64"}


def test_the_command_reads_committed_compact_records_and_writes_only_with_out(tmp_path, capsys, monkeypatch):
    from ddfbench.report import compact
    recs = [{**r, "key": f"{r['model']}-{i}",
             "experiment": "render_matched" if r["family"] == "neural_sdf" else "render_time"}
            for i, r in enumerate(records(sdf_loose_error=5e-3))]
    time_file, matched_file = tmp_path / "rt.jsonl.gz", tmp_path / "rm.jsonl.gz"
    compact.write_compact([r for r in recs if r["experiment"] == "render_time"], str(time_file))
    compact.write_compact([r for r in recs if r["experiment"] == "render_matched"], str(matched_file))
    monkeypatch.chdir(tmp_path)  # without --out nothing is written, here or below (it once wrote reports/...)
    assert matched.main([str(time_file), str(matched_file)]) == 0
    assert 'neural_sdf {"eps_abs": 0.001}' in capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["rm.jsonl.gz", "rt.jsonl.gz"]
    assert matched.main([str(time_file), str(matched_file), "--out", str(tmp_path / "out")]) == 0
    table = (tmp_path / "out" / "matched.csv").read_text()
    assert 'neural_sdf {""eps_abs"": 0.001}' in table and "mesh_lod500" not in table  # the full mesh matches
    assert matched.main([str(tmp_path / "none.jsonl.gz")]) == 2


def test_no_run_to_match_or_a_bad_out_is_one_line_and_nothing_written(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    assert matched.main([str(tmp_path / "empty"), "--out", str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err == (f"ddfbench.report.matched: {tmp_path / 'empty'}: no finished ddf_tuned run "
                                       "beside another family's on its shape and frame size: nothing written\n")
    assert not (tmp_path / "out").exists()
    from ddfbench.report import compact

    compact.write_compact([{**r, "key": f"k{i}", "experiment": "render_time"} for i, r in enumerate(records(5e-3))],
                          str(tmp_path / "rt.jsonl.gz"))
    (tmp_path / "file").write_text("")
    assert matched.main([str(tmp_path / "rt.jsonl.gz"), "--out", str(tmp_path / "file")]) == 2
    assert capsys.readouterr().err.endswith("exists and is not a folder: nothing written\n")


@pytest.mark.slow
def test_render_matched_grid_sweeps_tracer_settings_of_the_sdf_families():
    from ddfbench.report.status import expected_grid

    jobs, _ = expected_grid("/nonexistent/render_matched", ["+experiment=render_matched"])
    assert len(jobs) == 2 * 4 * 2 * 3 and len({j.key for j in jobs}) == len(jobs)
