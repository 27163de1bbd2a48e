"""Bad input, second round (issue 48): nothing runs forever, nothing stale, nothing outside out_dir, no key
ignored in silence, no record that breaks the report, every value checked, filesystem faults in one line, one
fit per key at a time. In process (runner.run, the CLI's checks), so each case costs milliseconds."""

import errno
import json
import os
import stat
import threading
import time

import numpy as np
import pytest
import trimesh

from ddfbench import cli
from ddfbench.core.errors import InputError
from ddfbench.fit.budget import fit_limit
from ddfbench.run import runner, runs
from ddfbench.run.runs import config_key, find_records, is_done
from ddfbench.truth.oracle import Oracle
from ddfbench.truth.shapes import normalize, validate
from tests.hard_cases.conftest import compose

SMALL = ("shape=cube", "model=mesh", "sampling=random", "sampling.n_samples=2000")


def job(tmp_path, *overrides):
    return compose(*SMALL, *overrides, out_dir=tmp_path / "out")


def files_outside(root, out_dir):
    """Every file under root that is not under out_dir."""
    found = [os.path.join(d, f) for d, _, fs in os.walk(root) for f in fs]
    return [f for f in found if not os.path.abspath(f).startswith(os.path.abspath(out_dir) + os.sep)]


# ---- runs that never end ----------------------------------------------------------------------------
def test_a_nan_time_budget_is_a_failed_record_naming_it(tmp_path):
    rec = runner.run({**job(tmp_path), "train": {**job(tmp_path)["train"], "max_seconds": float("nan")}})
    assert rec["status"] == "failed" and rec["error"].startswith("train.max_seconds=nan: must be")


def test_a_steps_budget_outside_an_experiment_takes_the_models_fit_steps(tmp_path):
    cfg = compose("model=neural_sdf", "train.budget=steps", out_dir=tmp_path)
    assert fit_limit(cfg["train"], cfg["model"], None).max_steps == cfg["model"]["fit_steps"] == 3000
    cfg = compose("model=neural_sdf", "train.budget=steps", "train.max_steps=7", out_dir=tmp_path)
    assert fit_limit(cfg["train"], cfg["model"], None).max_steps == 7


# ---- stale results ----------------------------------------------------------------------------------
def test_a_changed_mesh_file_is_a_new_run(tmp_path):
    path = tmp_path / "shape.obj"
    trimesh.creation.box().export(path)
    cfg = compose("shape=file", f"shape.path={path}", "model=mesh", out_dir=tmp_path)
    first = config_key(cfg)
    trimesh.creation.icosphere(1).export(path)
    assert config_key(cfg) != first
    assert config_key(compose("shape=cube", "model=mesh", out_dir=tmp_path)) == config_key(
        compose("shape=cube", "model=mesh", out_dir=tmp_path))  # a built-in shape reads no file: the key holds


# ---- writes outside out_dir -------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["../../x", "/tmp/elsewhere", "", ".cache", ".hydra", "a/b", "..", "x" * 101])
def test_an_unsafe_experiment_name_is_refused_before_anything_is_written(tmp_path, name):
    with pytest.raises(InputError, match=r"^experiment_name="):
        runner.run({**job(tmp_path), "experiment_name": name})
    assert files_outside(tmp_path, tmp_path / "out") == [] and not (tmp_path / "out").exists()


# ---- silently ignored keys --------------------------------------------------------------------------
@pytest.mark.parametrize("section,key,named", [("train", "max_step", "did you mean max_steps"),
                                               ("eval", "foo", "eval.foo: unknown key"),
                                               ("scene", "bogus", "scene.bogus: unknown key"),
                                               ("oracle", "backnd", "did you mean backend"),
                                               (None, "sed", "did you mean seed")])
def test_a_key_nothing_reads_is_a_failed_record_naming_it(tmp_path, section, key, named):
    cfg = compose(*SMALL, "scene=depth", out_dir=tmp_path / "out") if section == "scene" else job(tmp_path)
    if section is None:
        cfg[key] = 3
    else:
        cfg[section] = {**cfg[section], key: 3}
    rec = runner.run(cfg)
    assert rec["status"] == "failed" and named in rec["error"], rec["error"]


@pytest.mark.parametrize("arg,named", [("train.max_step=5", "train.max_step: unknown key (did you mean max_steps"),
                                       ("+train.max_step=5", "train.max_step: unknown key (did you mean max_steps"),
                                       ("++eval.n_pointz=3", "eval.n_pointz: unknown key (did you mean n_points?"),
                                       ("sed=3", "sed: unknown key (did you mean seed"),
                                       ("eval.n_pointz=3", "eval.n_pointz: unknown key (did you mean n_points?"),
                                       ("oracle.backnd=embree", "oracle.backnd: unknown key (did you mean backend?"),
                                       ("scene.widht=3", "scene.widht: unknown key (did you mean width?"),
                                       ("experiment=ablation", "experiment=ablation: experiment is a config group "
                                                               "outside the defaults: use +experiment=ablation"),
                                       ("form=quick", "form=quick: form is a config group outside the defaults: "
                                                      "use +form=quick")])
def test_an_undeclared_key_is_one_line_before_hydra_composes(arg, named):
    with pytest.raises(InputError) as err:
        cli.check_plain_keys(["model=mesh", arg])
    assert str(err.value).startswith(named) and "\n" not in str(err.value)


def test_plain_overrides_of_declared_keys_groups_and_hydra_pass_the_key_check():
    cli.check_plain_keys(["--multirun", "model=mesh,grid_sdf", "shape=cube", "seed=0,1", "capacity=null", "threads=1",
                          "train.max_steps=5", "eval.n_points=10", "oracle.backend=embree", "scene.width=8",
                          "scene.cameras.n=3", "scene.lights=[]",
                          "model.lr=1e-3", "++train.max_steps=5", "hydra/launcher=ray", "hydra.launcher.n_jobs=2",
                          "~tracking", "experiment_name=x"])


# ---- records that break the report forever ----------------------------------------------------------
@pytest.mark.parametrize("content", [{"status": "ok"}, {"status": "ok", "key": "k", "experiment": "e", "metrics": [1],
                                                        "cost": {}, "config": {}}, {"status": "done"}])
def test_a_record_that_is_not_one_is_rerun_and_skipped_by_the_report(tmp_path, capsys, content, monkeypatch):
    cfg = job(tmp_path)
    path = runs.record_path(str(tmp_path / "out"), "single", config_key(cfg))
    os.makedirs(os.path.dirname(path))
    with open(path, "w") as fh:
        json.dump(content, fh)
    assert not is_done(path)
    assert find_records(str(tmp_path / "out")) == []
    assert capsys.readouterr().err.count(path) == 1  # reported once, with its path
    from ddfbench.report.__main__ import main as report_main

    assert report_main([str(tmp_path / "out"), "--out", str(tmp_path / "rep")]) == 2  # no records: says so, no raise
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith(f"ddfbench: skipped {path}: not a run record")
    assert err[1:] == [f"ddfbench.report: {tmp_path / 'out'}: no run records: nothing written"]
    assert not os.path.exists(tmp_path / "rep")
    assert runner.run(cfg)["status"] == "ok" and is_done(path)  # the next launch runs it
    stray = tmp_path / "out" / "single" / "stray" / "record.json"
    stray.parent.mkdir()
    stray.write_text(json.dumps(content))
    from ddfbench.report import status

    monkeypatch.setattr(status, "expected_grid", lambda *args: ([], "a sweep"))  # as if a sweep had written them
    assert report_main([str(tmp_path / "out" / "single"), "--out", str(tmp_path / "rep"), "--plots", "none"]) == 0
    assert capsys.readouterr().err.count(f"skipped {stray}") == 1  # said once, though the sweep status reads it too


# ---- forced reruns -----------------------------------------------------------------------------------
def test_a_force_that_is_not_true_or_false_stops_before_the_ok_record_is_touched(tmp_path):
    cfg = job(tmp_path)
    path = runs.record_path(str(tmp_path / "out"), "single", config_key(cfg))
    assert runner.run(cfg)["status"] == "ok"
    before = open(path).read()
    with pytest.raises(InputError, match=r"^force='maybe': must be true or false$"):
        runner.run({**cfg, "force": "maybe"})
    assert open(path).read() == before and is_done(path)


def test_a_forced_rerun_killed_midway_leaves_no_record_that_vouches_for_its_files(tmp_path, monkeypatch):
    cfg = job(tmp_path)
    path = runs.record_path(str(tmp_path / "out"), "single", config_key(cfg))
    assert runner.run(cfg)["status"] == "ok"

    def killed(cfg, rdir, *args):  # the new fit's artifact is written, then the process dies
        open(os.path.join(rdir, "reconstruction.ply"), "w").close()
        raise KeyboardInterrupt

    monkeypatch.setattr(runner, "_stages", killed)
    with pytest.raises(KeyboardInterrupt):
        runner.run({**cfg, "force": True})
    assert not os.path.exists(path)  # the old ok record is gone: the next launch runs the key again
    monkeypatch.undo()
    assert runner.run(cfg)["status"] == "ok" and is_done(path)


def test_an_earlier_attempt_s_error_log_does_not_stay_beside_the_ok_record(tmp_path, monkeypatch):
    cfg = job(tmp_path)

    def broken(*args):
        raise RuntimeError("a stage broke")

    monkeypatch.setattr(runner, "_stages", broken)
    failed = runner.run(cfg)
    log = os.path.join(tmp_path / "out", "single", failed["key"], runner.ERROR_LOG)
    assert failed["error"] == "RuntimeError: a stage broke" and "a stage broke" in open(log).read()
    monkeypatch.undo()
    assert runner.run(cfg)["status"] == "ok" and not os.path.exists(log)  # the failed key runs again


# ---- unchecked values -------------------------------------------------------------------------------
@pytest.mark.parametrize("where,value,named", [
    ("domain", 0.0, "domain=0.0"), ("domain", -1, "domain=-1"), ("oracle.occupancy_rays", 0, "oracle.occupancy_rays=0"),
    ("model.faces", -1, "model.faces=-1"), ("train.probe_points", 0, "train.probe_points=0"),
    ("eval.mesh_resolution", 1, "eval.mesh_resolution=1"), ("eval.radii", [0.01, -1], "eval.radii[1]=-1"),
    ("train.max_epochs", float("inf"), "train.max_epochs=inf"),
    ("seed", 2**63, "seed=9223372036854775808: must be an integer >= 0 and < 2**63"),
    ("eval.n_points", 10**12, "eval.n_points=1000000000000: needs about 600 bytes a point (6e+05 GB), more than this "
     "machine's"),
    ("quiet", "loud", "quiet='loud': must be true or false"),
    ("eval.noise_floor", 2, "eval.noise_floor=2: must be true or false")])
def test_an_out_of_range_value_is_a_failed_record_naming_it(tmp_path, where, value, named):
    cfg = job(tmp_path)
    section, _, key = where.partition(".")
    if key:
        cfg[section] = {**cfg[section], key: value}
    else:
        cfg[section] = value
    rec = runner.run(cfg)
    assert rec["status"] == "failed" and rec["error"].startswith(named), rec["error"]


def test_the_field_box_must_hold_the_unit_cube_and_checkpoint_every_zero_means_none(tmp_path):
    """domain is the field box's half side: 0.5 or less cuts the normalized shape (refused, though positive); a
    checkpoint interval of 0 is allowed (no checkpoints) and a negative one is not. Kills `domain > 0` for
    `> 0.5` and `checkpoint_every > 0` for `>= 0` in checks.check_numbers."""
    from ddfbench.run.checks import check_job

    for domain in (0.5, 0.3):
        with pytest.raises(InputError, match=f"domain={domain}: must be a finite number > 0.5"):
            check_job({**job(tmp_path), "domain": domain})
    check_job({**job(tmp_path), "domain": 0.6, "checkpoint_every": 0})
    with pytest.raises(InputError, match="checkpoint_every=-1: must be a finite number of seconds >= 0"):
        check_job({**job(tmp_path), "checkpoint_every": -1})


@pytest.mark.parametrize("model,section,key", [("mesh", "model", "family"), ("neural_sdf", "sampling", "strategy")])
def test_a_yaml_that_names_no_module_is_one_line_saying_so(tmp_path, model, section, key):
    cfg = job(tmp_path, f"model={model}")
    cfg[section] = {k: v for k, v in cfg[section].items() if k != key}
    rec = runner.run(cfg)
    assert rec["status"] == "failed" and rec["error"].startswith(f"{section}.{key}: not set: the {section} YAML names")


def test_a_family_that_builds_from_the_mesh_needs_no_sampler(tmp_path):
    from ddfbench.run.checks import check_job

    cfg = job(tmp_path)  # model=mesh: sample_kind None, the runner draws no samples
    check_job({k: v for k, v in cfg.items() if k != "sampling"})


def test_a_name_beside_a_mesh_file_is_one_line_saying_the_file_names_the_shape(tmp_path):
    cfg = compose("shape=file", "shape.path=/data/big.obj", "shape.name=chair", "model=mesh", out_dir=tmp_path)
    rec = runner.run(cfg)
    assert rec["status"] == "failed" and rec["error"] == (
        "shape.name='chair': with shape=file the shape takes its file's name (big); drop shape.name")


@pytest.mark.parametrize("value", [-1e-3, float("nan"), 0.0])
def test_a_bad_learning_rate_is_named(tmp_path, value):
    rec = runner.run(compose("shape=cube", "model=neural_sdf", "sampling=random", "sampling.n_samples=2000",
                             f"model.lr={value}", out_dir=tmp_path))
    assert rec["status"] == "failed" and rec["error"].startswith(f"model.lr={value}"), rec["error"]


@pytest.mark.parametrize("scale", [1e200, 1e300, 1e-13, 1e-300])
def test_extreme_coordinates_normalize_to_the_unit_cube(scale):
    base = trimesh.creation.icosphere(2)
    mesh, _ = validate(trimesh.Trimesh(base.vertices * scale + 2 * scale, base.faces, process=False), "x")
    out, transform = normalize(mesh)
    assert np.ptp(out.vertices, axis=0).max() == pytest.approx(1.0)
    assert np.allclose(out.vertices, normalize(base)[0].vertices, atol=1e-12)  # the same shape, whatever its units
    assert np.isfinite(transform["scale"]) and transform["scale"] > 0


def test_a_shape_too_small_to_scale_is_refused_by_name():
    base = trimesh.creation.icosphere(2)
    with pytest.raises(InputError, match="too small to scale to the unit cube"):
        validate(trimesh.Trimesh(base.vertices * 1e-305 + 1e-297, base.faces, process=False), "tiny.obj")


def test_a_changed_mesh_files_records_say_which_file_they_measured(tmp_path):
    path = tmp_path / "shape.obj"
    recs = []
    for mesh in (trimesh.creation.box(), trimesh.creation.icosphere(1)):
        mesh.export(path)
        recs.append(runner.run(compose("shape=file", f"shape.path={path}", "model=mesh", "scene=none",
                                       out_dir=tmp_path / "out")))
    assert [r["status"] for r in recs] == ["ok", "ok"] and recs[0]["key"] != recs[1]["key"]
    assert recs[0]["config"]["inputs"]["shape.path"] != recs[1]["config"]["inputs"]["shape.path"]


def test_float64_directions_far_from_unit_are_directions(sphere):
    o = np.array([[0.0, 0.0, -0.9], [0.0, 0.0, -0.9]])
    t = Oracle(sphere.mesh).hit_distance(o, np.array([[0.0, 0.0, 1e-50], [0.0, 0.0, 1e39]]))
    assert np.isfinite(t).all() and t[0] == pytest.approx(t[1])


def test_directions_are_made_unit_and_every_backend_agrees(sphere, rng):
    o = rng.uniform(-0.5, 0.5, (256, 3)) * [1, 1, 0] + [0, 0, -0.6]
    d = np.tile([0.0, 0.0, 1.0], (256, 1)) + rng.normal(0, 0.1, (256, 3))
    unit = d / np.linalg.norm(d, axis=1, keepdims=True)
    backends = ["open3d", "embree"] + (["warp"] if _has_warp() else [])
    answers = []
    for backend in backends:
        oracle = Oracle(sphere.mesh, backend=backend)
        t_scaled, t_unit = oracle.hit_distance(o, 3.0 * d), oracle.hit_distance(o, unit)
        assert np.array_equal(np.isfinite(t_scaled), np.isfinite(t_unit)) and np.isfinite(t_unit).sum() > 100
        np.testing.assert_allclose(t_scaled[np.isfinite(t_unit)], t_unit[np.isfinite(t_unit)], rtol=1e-5)
        answers.append(t_scaled)
    for other in answers[1:]:
        hit = np.isfinite(answers[0]) & np.isfinite(other)
        np.testing.assert_allclose(other[hit], answers[0][hit], atol=1e-5)
    with pytest.raises(InputError, match="ray directions: 1 of 2 are zero"):
        Oracle(sphere.mesh).hit_distance(o[:2], [[0, 0, 1], [0, 0, 0]])


def _has_warp() -> bool:
    import importlib.util

    return importlib.util.find_spec("warp") is not None


# ---- filesystem faults ------------------------------------------------------------------------------
def test_an_out_dir_that_is_a_file_stops_the_command_in_one_line(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError, match=r"^out_dir=.*: exists and is not a folder$"):
        cli.check_out_dir([f"out_dir={tmp_path / 'f'}"])
    with pytest.raises(InputError, match=r"^out_dir=.*: cannot be made"):
        cli.check_out_dir([f"out_dir={tmp_path / 'f' / 'below'}"])
    cli.check_out_dir([f"out_dir={tmp_path / 'new'}"])
    assert (tmp_path / "new").is_dir()


def test_a_run_whose_folder_cannot_be_made_returns_a_failed_record(tmp_path):
    (tmp_path / "f").write_text("x")
    rec = runner.run({**job(tmp_path), "out_dir": str(tmp_path / "f")})
    assert rec["status"] == "failed" and rec["error"].startswith(f"out_dir={tmp_path / 'f'}: the run's files cannot")


def test_a_full_disk_at_the_record_leaves_nothing_half_written(tmp_path, monkeypatch):
    def full(path, data):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(runs, "write_json_atomic", full)
    rec = runner.run(job(tmp_path))
    assert rec["status"] == "failed" and "No space left on device" in rec["error"]
    assert find_records(str(tmp_path)) == []


# ---- races ------------------------------------------------------------------------------------------
def test_concurrent_launches_of_one_key_fit_once(tmp_path, monkeypatch):
    stages, real = [], runner._stages

    def slow_stages(*args):
        stages.append(1)
        time.sleep(0.5)
        real(*args)

    monkeypatch.setattr(runner, "_stages", slow_stages)
    cfg, got = job(tmp_path), []
    threads = [threading.Thread(target=lambda: got.append(runner.run(cfg))) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(stages) == 1 and [r["status"] for r in got] == ["ok", "ok"] and got[0]["key"] == got[1]["key"]


def test_a_record_is_readable_like_every_other_output(tmp_path):
    umask = os.umask(0o022)
    try:
        rec = runner.run(job(tmp_path))
    finally:
        os.umask(umask)
    record = os.stat(runs.record_path(str(tmp_path / "out"), "single", rec["key"])).st_mode
    mesh = os.stat(os.path.join(tmp_path / "out", "single", rec["key"], "gt_mesh.ply")).st_mode
    assert stat.S_IMODE(record) == stat.S_IMODE(mesh) == 0o644


def test_a_checkout_without_symlinks_is_told_how_to_get_its_configs(tmp_path, monkeypatch):
    from ddfbench.core import plugins
    from ddfbench.run.checks import check_conf_found

    link = tmp_path / "conf"
    link.write_text("../conf")  # what git writes for the link where core.symlinks is false
    monkeypatch.setattr(plugins, "CONF_DIR", str(link))
    with pytest.raises(InputError, match=r"conf: a file, not the link to conf/: this checkout was made without "
                                         r"symlinks \(git config core.symlinks true"):
        check_conf_found()
    link.unlink()
    with pytest.raises(InputError, match=r"conf: no configs there: install ddfbench with them"):
        check_conf_found()
