"""Fit checkpoints: an interrupted fit resumed from its checkpoint ends exactly where the uninterrupted fit
ends (weights, loss curve, probes), for every learned family and through the runner; a checkpoint of
other code or of another fit is not loaded."""

import os
import platform
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

import ddfbench
from ddfbench.core.plugins import CONF_DIR
from ddfbench.core.representation import Budget, FitData
from ddfbench.fit.checkpoint import FILE, Checkpoint, code_fingerprint
from ddfbench.models import load_family
from ddfbench.run import runner
from ddfbench.run.runs import find_records
from ddfbench.sampling.oracle_sdf import oracle_sdf_samples
from ddfbench.sampling.samples import Samples
from ddfbench.truth.oracle import Oracle
from tests.conftest import random_rays

STEPS = 12
# small members of each learned family, with what a resume must carry: dropout and a batch generator
# (DDF), a second optimizer and spectral-norm buffers (GAN), an eikonal term drawing uniform points (SDF)
FAMILIES = {
    "neural_sdf": {"family": "neural_sdf", "width": 32, "depth": 2, "batch": 256, "w_eikonal": 0.1},
    "ddf": {"family": "ddf", "width": 32, "depth": 2, "dropout": 0.2, "batch": 256, "pos_freqs": 2, "dir_freqs": 1},
    "gan_sdf": {"family": "gan_sdf", "batch": 16, "spectral_norm": True, "w_anchor": 1.0},
}


class Interrupted(BaseException):
    """What a killed process is to the fit: nothing after it runs."""


@pytest.fixture(scope="module")
def data(sphere):
    """Exact SDF and ray samples of the catalog sphere (conftest: one torch thread)."""
    oracle = Oracle(sphere.mesh)
    x, d = random_rays(np.random.default_rng(0), 4000)
    t = oracle.first_hit(x, d)[0]
    rays = Samples(x=x.astype(np.float32), d=d.astype(np.float32), t=t, hit=np.isfinite(t))
    sdf = oracle_sdf_samples(sphere.mesh, oracle, 4000, seed=0)
    return {"sdf": FitData(sdf, sphere.mesh, oracle), "rays": FitData(rays, sphere.mesh, oracle)}


def fit(name, data, checkpoint=None, stop_at_probe=None):
    """Fit a fresh member of `name` for STEPS steps (3 probes); the probe numbered stop_at_probe interrupts it.
    Returns (representation, stats)."""
    Family = load_family(name)
    rep = Family(FAMILIES[name])
    seen = []

    def probe(_rep):
        if len(seen) + 1 == stop_at_probe:
            raise Interrupted
        seen.append(len(seen))
        return {"probe": float(len(seen))}

    budget = Budget(max_steps=STEPS, max_seconds=1e6, seed=3, n_probes=3, checkpoint=checkpoint)
    stats = rep.fit(data["sdf" if Family.sample_kind == "sdf" else "rays"], budget, probe)
    return rep, stats


def weights(rep):
    return {k: v.clone() for k, v in rep.net.state_dict().items()}


def losses(stats):
    return [(step, loss) for step, _, loss in stats.loss_curve]


@pytest.mark.parametrize("name", sorted(FAMILIES))
def test_an_interrupted_fit_resumed_from_its_checkpoint_ends_where_the_uninterrupted_fit_ends(name, data, tmp_path):
    straight_rep, straight = fit(name, data)
    ckpt = Checkpoint(str(tmp_path / "fit.pt"), every_s=0.0, tag="code-a")  # every step
    with pytest.raises(Interrupted):
        fit(name, data, ckpt, stop_at_probe=2)  # the second probe (step 4 of 12) is where the process dies
    assert os.path.exists(ckpt.path)
    rep, resumed = fit(name, data, ckpt)
    assert resumed.extra["resumed_at"] == [3]  # the last save before the interruption: after step 3
    assert resumed.steps == straight.steps == STEPS
    assert losses(resumed) == losses(straight)
    assert [p["step"] for p in resumed.probes] == [p["step"] for p in straight.probes]
    a, b = weights(rep), weights(straight_rep)
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a), name


def test_a_checkpoint_of_other_code_or_of_another_fit_is_not_loaded(data, tmp_path):
    path = str(tmp_path / "fit.pt")
    with pytest.raises(Interrupted):
        fit("neural_sdf", data, Checkpoint(path, every_s=0.0, tag="code-a"), stop_at_probe=2)
    _, other_code = fit("neural_sdf", data, Checkpoint(path, every_s=1e9, tag="code-b"))
    assert "resumed_at" not in other_code.extra and other_code.steps == STEPS
    _, fresh = fit("neural_sdf", data)
    assert losses(other_code) == losses(fresh)
    with pytest.raises(Interrupted):
        fit("neural_sdf", data, Checkpoint(path, every_s=0.0, tag="code-a"), stop_at_probe=2)
    _, other_fit = fit("ddf", data, Checkpoint(path, every_s=1e9, tag="code-a"))  # same file, another fit
    assert "resumed_at" not in other_fit.extra


def test_an_unreadable_checkpoint_starts_the_fit_over_and_a_finished_fit_is_not_trained_again(data, tmp_path):
    path = tmp_path / "fit.pt"
    path.write_bytes(b"cut short by a crash")
    _, fresh = fit("neural_sdf", data)
    ckpt = Checkpoint(str(path), every_s=1e9, tag="code-a")  # no save along the fit: only the final one
    rep, over = fit("neural_sdf", data, ckpt)
    assert "resumed_at" not in over.extra and losses(over) == losses(fresh)
    again_rep, again = fit("neural_sdf", data, ckpt, stop_at_probe=1)  # a probe would interrupt: none runs
    assert again.extra["resumed_at"] == [STEPS] and losses(again) == losses(over) and again.probes == over.probes
    a, b = weights(again_rep), weights(rep)
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_the_code_fingerprint_follows_the_source(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "a.py").write_text("x = 1\n")
    (tmp_path / "sub" / "b.py").write_text("y = 2\n")
    before = code_fingerprint(str(tmp_path))
    assert code_fingerprint(str(tmp_path)) == before and len(before) == 16
    (tmp_path / "sub" / "b.py").write_text("y = 3\n")
    assert code_fingerprint(str(tmp_path)) != before
    assert code_fingerprint() == code_fingerprint(os.path.dirname(ddfbench.__file__))  # by default: ddfbench's own


def test_a_checkpoint_of_another_fit_is_set_aside_not_overwritten_and_its_own_fit_takes_it_back(tmp_path):
    two, one = Checkpoint(str(tmp_path / "fit.pt"), tag="code-a"), Checkpoint(str(tmp_path / "fit.pt"), tag="code-a")
    two.save({"fit": "gan 2 threads", "step": 24787})  # hours of a fit on 2 threads
    assert one.load("gan 1 thread") is None  # rerun by mistake on 1 thread: starts over ...
    one.save({"fit": "gan 1 thread", "step": 5})  # ... and saves where the 2-thread fit was
    assert two.load("gan 2 threads")["step"] == 24787  # the 2-thread rerun goes on from its own
    assert one.load("gan 1 thread")["step"] == 5  # and the 1-thread one from its own
    newer = Checkpoint(str(tmp_path / "fit.pt"), tag="code-b")
    assert newer.load("gan 2 threads") is None  # other code does not resume either fit
    assert len(list(tmp_path.glob("fit.pt.*.pt"))) == 2
    (tmp_path / "fit.pt").write_bytes(b"cut short")  # an unreadable file does not hide a set-aside one
    assert two.load("gan 2 threads")["step"] == 24787
    one.remove()  # an ok record: every checkpoint of the run goes
    assert not list(tmp_path.iterdir())


def test_a_checkpoint_that_cannot_be_moved_aside_starts_the_fit_over_without_an_error(tmp_path, monkeypatch):
    ckpt = Checkpoint(str(tmp_path / "fit.pt"), tag="code-a")
    ckpt.save({"fit": "gan 2 threads", "step": 7})

    def read_only(*args):
        raise PermissionError("read-only file system")

    monkeypatch.setattr(os, "replace", read_only)
    assert ckpt.load("gan 1 thread") is None  # the fit starts over; its run does not fail
    monkeypatch.undo()
    assert ckpt.load("gan 2 threads")["step"] == 7


class Stranger:
    """An object a results folder from someone else could smuggle into a checkpoint."""


def test_a_checkpoint_holding_anything_but_tensors_numbers_and_containers_is_not_loaded(tmp_path):
    ckpt = Checkpoint(str(tmp_path / "fit.pt"), tag="code-a")
    state = {"fit": "f", "step": 3, "rng": {"key": [1, 2, 3]}, "w": torch.ones(2)}
    ckpt.save(state)
    assert ckpt.load("f")["step"] == 3
    ckpt.save({**state, "extra": Stranger()})  # unpickling it would run a stranger's code
    assert ckpt.load("f") is None


TINY = ["-m", "model=neural_sdf", "shape=sphere", "eval=smoke", "eval.n_points=2000", "eval.mesh_resolution=20",
        "scene=none", "sampling=random", "sampling.n_samples=4000", "train.budget=steps", "train.max_steps=400",
        "train.n_probes=0", "model.batch=2048", "train.device=cpu", "threads=1", "quiet=true"]


def run_cli(out_dir, *extra, kill_when_checkpointed=False):
    """One tiny neural-SDF job; with kill_when_checkpointed, SIGKILL it once its fit has saved a checkpoint."""
    cmd = [sys.executable, "-m", "ddfbench", *TINY, *extra, f"out_dir={out_dir}"]
    if not kill_when_checkpointed:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr[-2000:]
        return
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 300
    while not any(f == "fit_checkpoint.pt" for _, _, files in os.walk(out_dir) for f in files):
        assert proc.poll() is None and time.time() < deadline, "the job ended before it saved a checkpoint"
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()


@pytest.mark.slow
def test_a_killed_run_rerun_goes_on_from_its_checkpoint_and_the_record_says_so(tmp_path):
    run_cli(tmp_path / "straight")
    run_cli(tmp_path / "killed", "checkpoint_every=0.5", kill_when_checkpointed=True)
    assert not find_records(str(tmp_path / "killed"))  # killed mid-fit: no record, half-written or whole
    run_cli(tmp_path / "killed", "checkpoint_every=0.5")
    (straight,), (resumed,) = find_records(str(tmp_path / "straight")), find_records(str(tmp_path / "killed"))
    assert resumed["key"] == straight["key"]  # checkpoint_every does not change what the run computes
    assert resumed["status"] == "ok" and "resumed_at" not in straight["fit"]
    assert 0 < resumed["fit"]["resumed_at"][0] < 400  # killed mid-fit, not after its final save
    assert [r[::2] for r in resumed["fit"]["loss_curve"]] == [r[::2] for r in straight["fit"]["loss_curve"]]
    assert resumed["metrics"] == straight["metrics"]
    assert not [f for _, _, files in os.walk(tmp_path) for f in files if f.startswith("fit_checkpoint")]


def _failed_after_its_fit(tmp_path, monkeypatch) -> dict:
    """A 40-step run whose measuring fails (a full disk) after its fit ended; its config."""
    with initialize_config_dir(CONF_DIR, version_base="1.3"):
        cfg = OmegaConf.to_container(compose("config", overrides=[*TINY[1:], "train.max_steps=40", "eval.noise_floor=false",
                                                                  f"out_dir={tmp_path}"]), resolve=True)

    def full_disk(*args, **kwargs):
        raise OSError("No space left on device")

    with monkeypatch.context() as patch:
        patch.setattr(runner, "geometry_metrics", full_disk)
        failed = runner.run(cfg)
    assert failed["status"] == "failed" and failed["fit"]["status"] == "ok"
    assert [f for _, _, files in os.walk(tmp_path) for f in files if f == FILE]
    return cfg


def test_a_run_that_fails_after_its_fit_keeps_the_checkpoint_and_its_rerun_does_not_train_again(tmp_path, monkeypatch):
    cfg = _failed_after_its_fit(tmp_path, monkeypatch)
    rerun = runner.run(cfg)
    assert rerun["status"] == "ok" and rerun["fit"]["resumed_at"] == [40]
    assert rerun["env"]["glibc_heap_kept"] is (platform.libc_ver()[0] == "glibc")  # the record says how it ran
    assert not [f for _, _, files in os.walk(tmp_path) for f in files if f == FILE]


def test_a_forced_rerun_of_a_run_that_failed_after_its_fit_fits_anew(tmp_path, monkeypatch):
    cfg = _failed_after_its_fit(tmp_path, monkeypatch)
    forced = runner.run({**cfg, "force": True})
    assert forced["status"] == "ok" and forced["fit"]["steps"] == 40
    assert "resumed_at" not in forced["fit"]  # the kept checkpoint was deleted, not resumed
    assert not [f for _, _, files in os.walk(tmp_path) for f in files if f.startswith("fit_checkpoint")]
