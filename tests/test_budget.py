"""Fit budgets (ddfbench.fit.budget): steps and epochs fix the work, wall-clock is labelled as such; the runner
records the bound that ended a fit, the epochs made, and fits a seeded subset at train.n_labels."""

import math
import subprocess
import sys

import pytest

from ddfbench.core.errors import InputError
from ddfbench.fit.budget import entry_per_batch, fit_limit, fit_record, sample_batch
from ddfbench.run.runs import find_records

TRAIN = {"max_steps": 1000, "max_seconds": 5.0, "max_epochs": 2.5}


def test_steps_and_epochs_have_no_time_limit_and_wall_clock_keeps_it():
    steps = fit_limit({**TRAIN, "budget": "steps"}, {"batch": 100}, 1000)
    assert (steps.max_steps, steps.max_seconds) == (1000, math.inf)
    epochs = fit_limit({**TRAIN, "budget": "epochs"}, {"batch": 300}, 1000)
    assert (epochs.max_steps, epochs.max_seconds) == (9, math.inf)  # ceil(2.5 * 1000 / 300)
    assert fit_limit({**TRAIN, "budget": "epochs"}, {"batch": 250}, 1000).max_steps == 10
    clock = fit_limit({**TRAIN, "budget": "wall-clock"}, {}, None)
    assert (clock.max_steps, clock.max_seconds) == (1000, 5.0)


def test_an_epoch_counts_the_draws_from_the_sample_set_not_a_visibility_heads_entry_labels():
    """The DDF with a visibility head fills entry_share of its batch with entry labels the label count leaves out:
    one epoch over 1,536,000 ray samples at batch 2048 and share 0.25 is 1,000 steps of 1,536 samples (it was 750
    steps, 0.75 passes). A model without the head (clamp visibility) draws its whole batch."""
    head = {"batch": 2048, "visibility": "head", "entry_share": 0.25}
    assert entry_per_batch(head) == 512 and sample_batch(head) == 1536
    assert entry_per_batch({**head, "batch": 500}) == 124  # even: as many entry hits as misses
    epoch = {**TRAIN, "budget": "epochs", "max_epochs": 1, "max_steps": None}
    assert fit_limit(epoch, head, 1_536_000).max_steps == 1000
    assert fit_record(fit_limit(epoch, head, 1_536_000), "max_steps", 1000, head, 1_536_000)["epochs"] == 1.0
    clamp = {**head, "visibility": "clamp"}
    assert entry_per_batch(clamp) == 0 and fit_limit(epoch, clamp, 1_536_000).max_steps == 750
    # a fit whose lines gave one class alone draws no entry labels: its record counts the whole batch a step
    assert fit_record(fit_limit(epoch, head, 1_536_000), "max_steps", 1000, head, 1_536_000, 0)["epochs"] == 2048 / 1536


def test_the_record_names_the_bound_that_ended_the_fit():
    limit = fit_limit({**TRAIN, "budget": "wall-clock"}, {"batch": 100}, 1000)
    assert fit_record(limit, "max_seconds", 30, {"batch": 100}, 1000) == {"budget": "wall-clock", "epochs": 3.0}
    steps = fit_limit({**TRAIN, "budget": "steps"}, {}, 1000)
    assert fit_record(steps, "max_steps", 30, {}, 1000) == {"budget": "steps", "epochs": None}  # no batch: no epochs


@pytest.mark.parametrize("train,message", [({"budget": "minutes"}, "train.budget 'minutes'"),
                                           ({"budget": "epochs", "max_epochs": None}, "train.max_epochs None"),
                                           ({"budget": "epochs", "max_epochs": 0}, "train.max_epochs 0")])
def test_bad_budgets_name_the_key(train, message):
    with pytest.raises(InputError, match=message):
        fit_limit({**TRAIN, **train}, {"batch": 100}, 1000)


@pytest.mark.slow
def test_an_epoch_budget_on_a_label_subset_runs_and_is_recorded(tmp_path):
    # ddf_tuned takes its visibility head and entry_share from the family's defaults (conf/model/ddf.yaml)
    args = ["model=ddf_tuned", "model.width=16", "model.depth=2", "model.batch=500", "shape=sphere", "eval=smoke",
            "eval.n_points=1000", "eval.mesh_resolution=16", "scene=none", "sampling=random",
            "sampling.n_samples=3000", "train.budget=epochs", "train.max_epochs=2", "train.n_labels=1000",
            "train.n_probes=0", "threads=1", "quiet=true", f"out_dir={tmp_path}"]
    done = subprocess.run([sys.executable, "-m", "ddfbench", *args], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    (rec,) = find_records(str(tmp_path))
    # the batch of 500 holds 124 entry labels (entry_share 0.25, an even count): 376 of the 1000 labels a step
    assert rec["fit"]["entry_labels"] == 1000 and rec["fit"]["entry_per_batch"] == 124  # the subset keeps line_hit
    assert rec["fit"]["steps"] == 6 and rec["fit"]["epochs"] == pytest.approx(6 * 376 / 1000)  # ceil(2 x 1000 / 376)
    assert rec["fit"]["budget"] == "epochs"
    assert rec["sampling"]["n_samples"] == 1000 and rec["sampling"]["n_generated"] == 3000
    too_many = subprocess.run([sys.executable, "-m", "ddfbench", *args[:-1], "train.n_labels=5000",
                               f"out_dir={tmp_path}/b"], capture_output=True, text=True, timeout=600)
    assert too_many.returncode != 0 and "train.n_labels=5000" in too_many.stderr + too_many.stdout
