"""Runner settings that change what a record holds: the label subset's bounds and eval.noise_floor. In process
(runner.run), on the cube with small fits."""

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
