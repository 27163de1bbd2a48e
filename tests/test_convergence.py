"""+experiment=convergence: the band over seeds, time to reach k x the floor, and the report files."""

import math

import numpy as np
import pytest

from ddfbench.report import convergence
from ddfbench.report.__main__ import main as report_main
from ddfbench.run.runs import write_json_atomic


def run(model, shape, seed, probes, floor=1e-5):
    """A convergence record: probes [(seconds, chamfer)], F@0.01 = 1 - 10 x chamfer."""
    return {"key": f"{model}-{shape}-{seed}", "status": "ok", "schema_version": 1, "experiment": "convergence", "model": model,
            "family": model, "shape": {"name": shape}, "config": {"seed": seed}, "env": {"git_sha": "abc"},
            "overrides": [f"model={model}", f"shape={shape}", f"seed={seed}"], "sampling": {}, "cost": {},
            "metrics": {"chamfer_l2": probes[-1][1], "noise_floor": {"chamfer_l2": floor, "fscore": {"0.01": 1.0}}},
            "fit": {"probes": [{"step": i, "seconds": s, "chamfer_l2": c, "fscore@0.01": 1 - 10 * c}
                               for i, (s, c) in enumerate(probes)]}}


def test_band_holds_each_seed_at_its_last_probe():
    runs = [(np.array([1.0, 10.0]), np.array([4.0, 1.0])), (np.array([3.0, 30.0]), np.array([2.0, 0.5]))]
    t, med, lo, hi = convergence.band(runs)
    assert t.tolist() == [1, 3, 10, 30]
    assert lo.tolist() == [4, 2, 1, 0.5] and hi.tolist() == [4, 4, 2, 1]
    assert med.tolist() == [4, 3, 1.5, 0.75]


def test_time_to_floor_median_over_seeds_and_not_reached():
    recs = [run("ddf", "bunny", s, [(1, 1e-3), (10, 4e-5), (100, 1.5e-5 + 1e-6 * s)]) for s in range(3)]
    recs += [run("gan_sdf", "bunny", s, [(1, 1e-2), (100, 1e-3 if s else 4e-5)]) for s in range(3)]
    rows = {r["model"]: r for r in convergence.time_to_floor_rows(recs)}
    assert rows["ddf"]["median_s_5x"] == 10 and rows["ddf"]["median_s_2x"] == 100 and rows["ddf"]["reached_2x"] == 3
    assert rows["gan_sdf"]["reached_5x"] == 1 and math.isinf(rows["gan_sdf"]["median_s_5x"])  # 1 of 3: not reached
    md = convergence.to_markdown(list(rows.values()))
    assert "| ddf | bunny | 3 | 0.01 | 10 (3/3) | 100 (3/3) |" in md and "not reached (1/3)" in md


def test_a_failed_seed_is_a_seed_that_never_reached_the_floor():
    recs = [run("ddf", "bunny", s, [(1, 1e-3), (10, 4e-5)]) for s in range(2)]
    diverged = dict(run("ddf", "bunny", 2, [(1, 1e-3)]), status="failed")  # e.g. a non-finite loss
    row = convergence.time_to_floor_rows(recs + [diverged])[0]
    assert (row["n"], row["reached_5x"], row["median_s_5x"]) == (3, 2, 10)
    lost = [dict(run("gan_sdf", "bunny", s, [(1, 1e-3)]), status="failed") for s in range(3)]
    (row,) = [r for r in convergence.time_to_floor_rows(recs + [diverged, *lost]) if r["model"] == "gan_sdf"]
    assert (row["n"], row["reached_5x"]) == (3, 0) and math.isinf(row["median_s_5x"])
    assert "| gan_sdf | bunny | 3 |" in convergence.to_markdown([row]) and "not reached (0/3)" in convergence.to_markdown([row])
    alone = convergence.time_to_floor_rows(lost)  # no ok run of the shape: no floor to print
    assert "| gan_sdf | bunny | 3 | – | not reached (0/3) | not reached (0/3) | – |" in convergence.to_markdown(alone)


def test_time_to_floor_with_half_the_seeds_there_is_the_slower_of_those_that_did():
    """Four seeds, two reach 5 x the floor (at 10 s and 30 s): half got there, so the row gives a time (the lower
    median, 30 s), not 'not reached'; one of four is not enough."""
    recs = [run("ddf", "bunny", s, [(1, 1e-3), (10, 4e-5 if s == 0 else 1e-3), (30, 4e-5 if s < 2 else 1e-3)])
            for s in range(4)]
    (row,) = convergence.time_to_floor_rows(recs)
    assert row["reached_5x"] == 2 and row["median_s_5x"] == 30
    (row,) = convergence.time_to_floor_rows(recs[1:] + [run("ddf", "bunny", 9, [(1, 1e-3), (30, 1e-3)])])
    assert row["reached_5x"] == 1 and math.isinf(row["median_s_5x"])


def test_floor_is_over_the_ok_records_of_one_shape_or_of_every_shape():
    recs = [run("ddf", "bunny", 0, [(1, 1e-3)], floor=1e-5), run("ddf", "bone", 0, [(1, 1e-3)], floor=3e-5)]
    recs.append({**run("ddf", "bunny", 1, [(1, 1e-3)], floor=1.0), "status": "failed"})
    assert convergence.floor(recs, "bunny") == pytest.approx(1e-5)
    assert convergence.floor(recs) == pytest.approx(2e-5)
    assert math.isnan(convergence.floor(recs, "cow"))


def test_report_writes_the_band_plot_and_the_time_to_floor_table(tmp_path):
    for shape in ("bunny", "bone"):
        for s in range(3):
            r = run("neural_sdf", shape, s, [(0.3, 1e-3), (3, 1e-4), (30, 3e-5 * (1 + s))])
            write_json_atomic(str(tmp_path / "rec" / r["key"] / "record.json"), r)
    out = tmp_path / "rep"
    assert report_main([str(tmp_path / "rec"), "--out", str(out)]) == 0
    assert (out / "convergence.png").read_bytes()[:4] == b"\x89PNG"
    table = (out / "time_to_floor.md").read_text()
    assert "| neural_sdf | bone | 3 |" in table and "time to 2× floor" in table
    assert "Time to reach the noise floor" in (out / "report.md").read_text()
    assert "| neural_sdf | bone | 3 | 0 of 3 |" in (out / "stability.md").read_text()
    probes = (out / "probes.md").read_text()
    assert "| neural_sdf | bone | 2 | 2 | – | 30 | 0.09 | 0.999 |" in probes  # seed 2's last probe
    assert probes.count("| neural_sdf |") == 18 and "Every probe of every run" in (out / "report.md").read_text()


def test_a_sweep_renamed_by_experiment_name_keeps_its_experiment_files_sections(tmp_path):
    for s in range(2):
        r = {**run("gan_sdf", "bunny", s, [(1, 1e-3), (10, 1e-4)]), "experiment": "gan_epochs_b256"}
        r["overrides"] += ["+experiment=gan_epochs", "experiment_name=gan_epochs_b256"]
        write_json_atomic(str(tmp_path / "rec" / r["key"] / "record.json"), r)
    assert report_main([str(tmp_path / "rec"), "--out", str(tmp_path / "rep")]) == 0
    assert "| gan_sdf | bunny | 2 | 0 of 2 |" in (tmp_path / "rep" / "stability.md").read_text()
    assert (tmp_path / "rep" / "convergence.png").exists()  # gan_epochs' plots, not the default ones
    assert (tmp_path / "rep" / "report.md").read_text().startswith("# gan_epochs_b256")


def test_probe_rows_are_each_ok_runs_probes_in_seed_and_step_order_with_their_epoch():
    late = run("gan_sdf", "bunny", 1, [(5.0, 2e-3), (50.0, 4e-4)])
    late["fit"].update(steps=4, epochs=2.0)  # 2 steps an epoch
    early = run("gan_sdf", "bunny", 0, [(9.0, 3e-3)])
    failed = {**run("gan_sdf", "bunny", 2, [(1.0, 1e-3)]), "status": "failed"}
    rows = convergence.probe_rows([late, failed, early])
    assert [(r["seed"], r["step"]) for r in rows] == [(0, 0), (1, 0), (1, 1)]
    assert rows[2]["epoch"] == 0.5 and rows[2]["seconds"] == 50.0 and rows[2]["fscore@0.01"] == pytest.approx(0.996)
    assert math.isnan(rows[0]["epoch"])  # no epoch count in that record
    assert "| gan_sdf | bunny | 1 | 1 | 0.5 | 50 | 0.4 | 0.996 |" in convergence.probe_markdown(rows)


def test_probe_columns_keep_one_order_whatever_the_records_key_order():
    """A compact record's keys are sorted, a record.json's are as written: probes.csv must not follow either."""
    written = run("gan_sdf", "bunny", 0, [(9.0, 3e-3)])
    probe = written["fit"]["probes"][0]
    shuffled = {**written, "fit": {**written["fit"], "probes": [dict(sorted(probe.items(), reverse=True))]}}
    columns = [list(convergence.probe_rows([r])[0]) for r in (written, shuffled)]
    assert columns[0] == columns[1]
    assert columns[0][6:8] == ["seconds", "chamfer_l2"]  # after model, shape, seed, key, step, epoch


@pytest.mark.slow  # expands the sweep (~0.2 s a job)
def test_the_convergence_sweep_is_every_learned_family_on_bunny_and_bone_with_three_seeds():
    from ddfbench.core import plugins
    from ddfbench.models import learned_families
    from ddfbench.report.status import expected_grid

    jobs, _ = expected_grid("/nonexistent/convergence", ["+experiment=convergence"])
    swept = [dict(o.split("=", 1) for o in j.swept) for j in jobs]
    models = plugins.members("model", "convergence")
    family = {m: plugins.plugin_yaml("model", m)["family"] for m in models}
    assert set(family.values()) == set(learned_families())  # every learned family, and only those
    assert set(models) == {"ddf_tuned", "neural_sdf_tuned", "gan_sdf_tuned"}  # each family at its tuned values
    assert {(s["model"], s["shape"], s["seed"]) for s in swept} == {
        (m, sh, str(seed)) for m in models for sh in ("bunny", "bone") for seed in range(3)}
    assert len({j.key for j in jobs}) == len(models) * 6


@pytest.mark.slow  # expands the sweep (~0.2 s a job)
def test_paper_ddf_is_both_paper_presets_on_every_shape_at_ten_minutes():
    from hydra import compose, initialize_config_dir

    from ddfbench.core.plugins import CONF_DIR
    from ddfbench.report.status import expected_grid

    jobs, _ = expected_grid("/nonexistent/paper_ddf", ["+experiment=paper_ddf"])
    swept = {tuple(sorted(dict(o.split("=", 1) for o in j.swept).items())) for j in jobs}
    assert swept == {(("model", m), ("seed", str(s)), ("shape", sh)) for m in ("ddf_paper", "ddf_paper_lr")
                     for sh in ("bunny", "airplane", "cow", "bone") for s in range(3)}
    with initialize_config_dir(CONF_DIR, version_base="1.3"):
        train = compose("config", overrides=["+experiment=paper_ddf"]).train
    assert (train.budget, train.max_seconds) == ("wall-clock", 600)  # labelled: "does it train in 10 minutes"


def test_stability_counts_each_way_a_run_diverges_and_not_other_failures():
    steady = [(1, 1e-3), (10, 2e-4), (100, 1e-4)]
    recs = [run("gan_sdf", "bunny", 0, steady),
            run("gan_sdf", "bunny", 1, [(1, 1e-3), (10, 1e-4), (100, 2.5e-4)]),  # last 2.5x its best: regressed
            run("gan_sdf", "bunny", 2, [(1, 1e-3), (10, 1e-4), (100, 1.9e-4)]),  # 1.9x: within the margin
            {**run("gan_sdf", "bunny", 3, steady), "status": "failed", "fit": {"stop": "nonfinite"}},
            {**run("gan_sdf", "bunny", 4, steady), "status": "failed", "fit": {"stop": "max_steps"}},
            run("gan_sdf", "bunny", 5, steady), run("ddf", "bunny", 0, steady),
            run("gan_sdf", "bunny", 6, [(1, 1e-3), (10, 1e-4), (100, 3e-4)]),  # empty and regressed: one divergence
            {"status": "failed", "model": "gan_sdf", "shape": {"name": "bunny"}, "error": "bad file"},  # before any fit
            run("gan_sdf", "bunny", 7, steady), run("gan_sdf", "bunny", 8, steady)]
    recs[5]["metrics"]["empty_reconstruction"] = recs[7]["metrics"]["empty_reconstruction"] = True
    recs[9]["metrics"]["fscore"] = {"0.01": 0.0, "0.02": 0.0}  # a mesh nowhere near the shape: off it
    recs[10]["metrics"]["fscore"] = {"0.01": 0.0, "0.02": 1e-3}  # a few sampled points near it: a result
    rows = {r["model"]: r for r in convergence.stability_rows(recs)}
    gan = rows["gan_sdf"]
    assert (gan["runs"], gan["nonfinite"], gan["failed_other"], gan["empty"], gan["off"], gan["regressed"]) == (
        10, 1, 2, 2, 1, 2)
    assert gan["diverged"] == 5 and gan["worst_ratio"] == pytest.approx(3)
    assert rows["ddf"]["diverged"] == 0 and rows["ddf"]["worst_ratio"] == 1
    md = convergence.stability_markdown(list(rows.values()))
    assert "| gan_sdf | bunny | 10 | 5 of 10 | 1 | 2 | 1 | 2 | 3 | 2 |" in md
    assert "| ddf | bunny | 1 | 0 of 1 | 0 | 0 | 0 | 0 | 1 | 0 |" in md
