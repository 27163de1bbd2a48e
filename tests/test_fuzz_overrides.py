"""Property-based (hypothesis) over the override surface: random values for the numeric and path-forming keys
never give a traceback, never an ok record from an invalid value, never a file outside out_dir.

CI runs DDFBENCH_FUZZ_EXAMPLES (default 40) examples per property; a longer local run sets it higher."""

import math
import numbers
import os
import tempfile

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ddfbench.core.errors import InputError
from ddfbench.run import checks, runner, runs
from tests.hard_cases.conftest import compose

EXAMPLES = int(os.environ.get("DDFBENCH_FUZZ_EXAMPLES", "40"))
# CI draws the same examples every time (derandomize); a longer local run (the variable set) draws new ones
FUZZ = settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=[HealthCheck.too_slow],
                derandomize="DDFBENCH_FUZZ_EXAMPLES" not in os.environ)


def whole(least):
    return lambda v: (isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v)
                      and float(v).is_integer() and v >= least)


def real(above):
    return lambda v: isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(v) and v > above


def nullable(ok):
    return lambda v: v is None or ok(v)


# key -> what a valid value is, written apart from ddfbench.run.checks (the property's oracle)
def flag(v):
    return isinstance(v, bool)


VALID = {"domain": real(0.5), "seed": lambda v: whole(0)(v) and v < 2**63, "force": flag, "quiet": flag,
         "eval.noise_floor": flag, "eval.point_to_surface": flag, "threads": nullable(whole(0)), "checkpoint_every": nullable(
         lambda v: real(-math.inf)(v) and v >= 0), "train.budget": lambda v: v in ("steps", "wall-clock"),  # epochs: no max_epochs here
         "train.max_seconds": real(0.0), "train.max_steps": nullable(whole(1)),
         "train.max_epochs": nullable(real(0.0)), "train.n_labels": nullable(whole(1)), "train.n_probes": whole(0),
         "train.probe_points": whole(1), "eval.n_points": whole(1), "eval.mesh_resolution": whole(2),
         "oracle.occupancy_rays": whole(1)}
VALUES = st.one_of(st.none(), st.booleans(), st.integers(-10**9, 10**9), st.floats(allow_nan=True, allow_infinity=True),
                   st.sampled_from([0, 1, 2, 0.5, 0.6, 1e5, -0.0, 2.5, "steps", "epochs", "wall-clock"]),
                   st.text(max_size=4))
BASE = compose("shape=cube", "model=mesh", "sampling=random", "sampling.n_samples=2000", out_dir="unused")


def with_value(cfg, key, value):
    section, _, name = key.partition(".")
    return {**cfg, section: {**cfg[section], name: value}} if name else {**cfg, section: value}


@FUZZ
@given(key=st.sampled_from(sorted(VALID)), value=VALUES)
def test_a_value_passes_the_checks_exactly_when_it_is_valid(key, value):
    cfg = with_value(BASE, key, value)
    try:
        checks.check_job(cfg)
        accepted = True
    except InputError as err:
        accepted = False
        assert "\n" not in str(err) and str(err).startswith(f"{key}="), str(err)
    assert accepted == VALID[key](value), (key, value)


@FUZZ
@given(key=st.sampled_from(sorted(VALID)), value=VALUES)
def test_an_invalid_value_never_gives_an_ok_record_or_a_file_outside_out_dir(key, value):
    if VALID[key](value):
        return  # a valid value runs a job: the other tests cover that
    with tempfile.TemporaryDirectory() as root:
        out_dir = os.path.join(root, "out")
        try:
            rec = runner.run(with_value({**BASE, "out_dir": out_dir}, key, value))
        except InputError as err:  # force: refused before an earlier run's record is touched, nothing written
            assert key == "force" and str(err).startswith(f"{key}=") and not os.path.exists(out_dir), str(err)
        else:
            assert rec["status"] == "failed" and rec["error"].startswith(f"{key}="), rec["error"]
        outside = [os.path.join(d, f) for d, _, fs in os.walk(root) for f in fs if not d.startswith(out_dir)]
        assert outside == []


@FUZZ
@given(name=st.one_of(st.text(max_size=12), st.text(alphabet="./\\a0-_~ ", max_size=8)))
def test_an_experiment_name_is_refused_or_stays_inside_out_dir(name):
    try:
        safe = checks.safe_name(name, "experiment_name")
    except InputError as err:
        assert "\n" not in str(err) and str(err).startswith("experiment_name=")
        return
    out_dir = os.path.realpath("/tmp/out")
    folder = os.path.realpath(runs.run_dir(out_dir, safe, "k"))
    assert os.path.commonpath([folder, out_dir]) == out_dir and os.path.dirname(os.path.dirname(folder)) == out_dir
