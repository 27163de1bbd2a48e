"""Runner settings that change what a record holds: the label subset's bounds, eval.noise_floor and the probes. In
process (runner.run), on the cube with small fits."""

from ddfbench.run import runner
from tests.hard_cases.conftest import compose

FIT = ("shape=cube", "model=neural_sdf", "model.width=16", "model.depth=2", "sampling=random",
       "sampling.n_samples=2000", "train.budget=steps", "train.max_steps=2", "train.n_probes=0")


def test_a_label_subset_may_take_every_label_the_strategy_gave_but_not_one_more(tmp_path):
    """train.n_labels equal to the labels drawn fits on all of them; one more is a failed record naming the key.
    Kills `want >= len(samples)` for `want > len(samples)`."""
    whole = runner.run(compose(*FIT, "train.n_labels=2000", out_dir=tmp_path))
    assert whole["status"] == "ok", whole["error"]
    assert whole["sampling"]["n_samples"] == whole["sampling"]["n_generated"] == 2000
    over = runner.run(compose(*FIT, "train.n_labels=2001", out_dir=tmp_path))
    assert over["status"] == "failed"
    assert over["error"].startswith("train.n_labels=2001: sampling=random gave only 2000")


def test_eval_noise_floor_false_leaves_the_floor_out_of_the_record(tmp_path):
    """eval.noise_floor=false skips the GT-against-GT resample (its metrics are absent), true records it.
    Kills the runner ignoring eval.noise_floor."""
    mesh = ("shape=cube", "model=mesh")
    without = runner.run(compose(*mesh, "eval.noise_floor=false", out_dir=tmp_path))
    with_floor = runner.run(compose(*mesh, "eval.noise_floor=true", out_dir=tmp_path))
    assert without["status"] == with_floor["status"] == "ok"
    assert "noise_floor" not in without["metrics"] and with_floor["metrics"]["noise_floor"]["chamfer_l2"] > 0


def test_probes_mesh_at_most_at_the_evaluation_resolution_and_are_left_out_of_fit_s(tmp_path, monkeypatch):
    """A probe meshes at min(train.probe_resolution, eval.mesh_resolution), and its time is in fit_wall_s, not in
    fit_s (the training time). Kills the runner passing probe_resolution uncapped, and fit_s = fit_wall_s."""
    import time

    asked, real = [], runner._probe_fn

    def slow_probe_fn(points, resolution, radii):
        asked.append(resolution)
        probe = real(points, resolution, radii)
        return lambda rep: time.sleep(0.2) or probe(rep)

    monkeypatch.setattr(runner, "_probe_fn", slow_probe_fn)
    fit = [a for a in FIT if not a.startswith("train.n_probes")]
    rec = runner.run(compose(*fit, "train.n_probes=2", "train.probe_resolution=64", "eval.mesh_resolution=16",
                             out_dir=tmp_path))
    assert rec["status"] == "ok", rec["error"]
    assert asked == [16] and len(rec["fit"]["probes"]) >= 2
    assert rec["cost"]["fit_wall_s"] >= rec["cost"]["fit_s"] + 0.2 * len(rec["fit"]["probes"])
