"""The shared training loop: budgets, probes, schedule, seeding and the NaN guard."""

import time

import pytest
import torch

from ddfbench.core.errors import InputError
from ddfbench.core.representation import Budget
from ddfbench.fit import train
from ddfbench.fit.train import Schedule, probe_fractions, resolve_device, seed_everything, train_loop


def regression(seed=0):
    """A small linear regression problem and its step function."""
    seed_everything(seed)
    model = torch.nn.Linear(3, 1)
    w_true = torch.tensor([[1.0, -2.0, 0.5]])
    gen = torch.Generator().manual_seed(seed)

    def step_fn(step):
        x = torch.randn(64, 3, generator=gen)
        return ((model(x) - x @ w_true.T) ** 2).mean()

    return model, step_fn, w_true


def slowed(step_fn, seconds):
    """step_fn that first sleeps `seconds`: a step whose wall-clock cost is known."""

    def slow(step):
        time.sleep(seconds)
        return step_fn(step)

    return slow


def test_loss_decreases_and_step_budget_is_respected():
    model, step_fn, w_true = regression()
    opt = torch.optim.Adam(model.parameters(), lr=0.05)
    stats = train_loop(model, opt, step_fn, Budget(max_steps=300, max_seconds=1e6, n_probes=0), quiet=True)
    assert stats.status == "ok" and stats.steps == 300 and stats.extra["stop"] == "max_steps"
    assert torch.allclose(model.weight, w_true, atol=0.05)
    losses = [loss for _, _, loss in stats.loss_curve]
    assert losses[-1] < 0.01 * losses[0]
    assert [s for s, _, _ in stats.loss_curve] == sorted(s for s, _, _ in stats.loss_curve)
    assert stats.loss_curve[-1][0] == 300


def test_wall_clock_budget_stops_training():
    model, step_fn, _ = regression()
    opt = torch.optim.SGD(model.parameters(), lr=0.01)
    stats = train_loop(model, opt, slowed(step_fn, 0.01), Budget(max_steps=10**6, max_seconds=0.2, n_probes=0), quiet=True)
    assert stats.extra["stop"] == "max_seconds" and stats.status == "ok"
    assert 1 <= stats.steps < 10**6 and stats.seconds >= 0.2


def test_loss_curve_stays_short_on_long_runs():
    model, step_fn, _ = regression()
    opt = torch.optim.SGD(model.parameters(), lr=0.01)
    stats = train_loop(model, opt, step_fn, Budget(max_steps=3000, max_seconds=1e6, n_probes=0), quiet=True)
    assert 100 < len(stats.loss_curve) <= 600


def test_probes_are_log_spaced_in_eval_mode_and_not_charged_to_training():
    model, step_fn, _ = regression()
    model = torch.nn.Sequential(model, torch.nn.Dropout(0.5))
    modes = []

    def probe():
        modes.append(model.training)
        time.sleep(0.05)
        return {"metric": 1.0}

    opt = torch.optim.SGD(model.parameters(), lr=0.01)
    stats = train_loop(model, opt, step_fn, Budget(max_steps=81, max_seconds=1e6, n_probes=4), probe_fn=probe,
                       quiet=True)
    assert [p["step"] for p in stats.probes] == [3, 9, 27, 81]
    assert all(p["metric"] == 1.0 for p in stats.probes)
    assert modes == [False] * 4
    assert stats.extra["probe_seconds"] >= 0.2 and stats.seconds < stats.extra["probe_seconds"] + 10
    assert probe_fractions(3) == [1 / 9, 1 / 3, 1]


def test_probe_time_does_not_eat_the_wall_clock_budget(monkeypatch):
    """On a fake clock (a step costs 1/64 s, a probe 1 s: four times the 0.25 s budget) the budget buys exactly 16
    steps and every probe fires at its fraction of them; the probes' 3 s are counted apart."""
    now = [0.0]

    def spend(seconds):
        now[0] += seconds

    monkeypatch.setattr(train, "clock", lambda: now[0])  # the loop's training clock
    monkeypatch.setattr(train.time, "perf_counter", lambda: now[0])  # the probes' timer
    model, step_fn, _ = regression()
    opt = torch.optim.SGD(model.parameters(), lr=0.01)
    stats = train_loop(model, opt, lambda s: spend(1 / 64) or step_fn(s),
                       Budget(max_steps=10**6, max_seconds=0.25, n_probes=3), probe_fn=lambda: spend(1.0) or {},
                       quiet=True)
    assert stats.extra["stop"] == "max_seconds" and stats.steps == 16 and stats.seconds == 0.25
    assert [(p["step"], p["seconds"]) for p in stats.probes] == [(2, 2 / 64), (6, 6 / 64), (16, 0.25)]  # 1/9, 1/3, 1
    assert stats.extra["probe_seconds"] == 3.0


def test_schedule_factors_and_lr_applied():
    cos = Schedule("cosine", final_ratio=0.1)
    assert cos.factor(0.0) == pytest.approx(1.0) and cos.factor(1.0) == pytest.approx(0.1)
    assert cos.factor(0.5) == pytest.approx(0.55)
    exp = Schedule("exponential", final_ratio=0.01)
    assert exp.factor(0.5) == pytest.approx(0.1)
    assert Schedule("constant", warmup=0.2).factor(0.1) == pytest.approx(0.5)
    model, step_fn, _ = regression()
    opt = torch.optim.SGD(model.parameters(), lr=1.0)
    stats = train_loop(model, opt, lambda s: 0.0 * step_fn(s), Budget(max_steps=100, max_seconds=1e6, n_probes=0),
                       schedule=exp, quiet=True)
    assert stats.extra["final_lr"] == pytest.approx(0.01 ** 0.99)
    with pytest.raises(InputError, match=r"^lr schedule 'linear': unknown \(constant \| cosine \| exponential\)$"):
        Schedule("linear")
    with pytest.raises(InputError, match=r"^lr final_ratio 0\.0: must be in \(0, 1\]$"):
        Schedule.from_cfg({"lr_schedule": "cosine", "lr_final_ratio": 0, "lr_warmup": 0.0})


def test_seeded_runs_are_identical():
    weights = []
    for _ in range(2):
        model, step_fn, _ = regression(seed=3)
        opt = torch.optim.Adam(model.parameters(), lr=0.01)
        train_loop(model, opt, step_fn, Budget(max_steps=20, max_seconds=1e6, n_probes=0), quiet=True)
        weights.append(model.weight.detach().clone())
    assert torch.equal(weights[0], weights[1])


def test_nan_guard_fires_on_forced_divergence():
    model, step_fn, _ = regression()
    opt = torch.optim.SGD(model.parameters(), lr=1e6)  # diverges: weights overflow within a few steps
    stats = train_loop(model, opt, step_fn, Budget(max_steps=1000, max_seconds=1e6, n_probes=2),
                       probe_fn=lambda: {"x": 0.0}, quiet=True)
    assert stats.status == "failed" and stats.extra["stop"] == "nonfinite"
    assert stats.message.startswith("step ") and "non-finite" in stats.message
    assert stats.steps < 1000


def test_cuda_cadence_times_the_cold_step_apart():
    """On CUDA the host reads losses and the clock once per weight_check_every steps; the first step is
    a window of its own, so a 20-step fit's curve says how long its cold step took (bench.training's warm
    rate divides by the seconds after it). The cadence is chosen by the budget's device name alone, so a
    CPU module under device="cuda" runs the CUDA bookkeeping."""
    model, step_fn, _ = regression()
    opt = torch.optim.SGD(model.parameters(), lr=0.01)

    def cold_first(step):
        time.sleep(0.2 if step == 0 else 0.001)
        return step_fn(step)

    stats = train_loop(model, opt, cold_first, Budget(max_steps=20, max_seconds=1e6, n_probes=0, device="cuda"),
                       weight_check_every=50, quiet=True)
    seconds = {step: sec for step, sec, _ in stats.loss_curve}
    assert sorted(seconds) == list(range(1, 21)) and stats.status == "ok"
    assert 0.2 <= seconds[1] < stats.seconds and len({seconds[s] for s in range(2, 21)}) == 1
    assert stats.seconds - seconds[1] < 0.2  # the 19 warm steps


def test_nan_guard_catches_weights_that_go_bad_without_a_bad_loss():
    model, step_fn, _ = regression()
    opt = torch.optim.SGD(model.parameters(), lr=0.0)

    def poison(step):
        if step == 7:
            with torch.no_grad():
                model.bias.fill_(float("inf"))
        return 0.0 * model.weight.sum()  # stays finite (0 * finite weights)

    stats = train_loop(model, opt, poison, Budget(max_steps=200, max_seconds=1e6, n_probes=0),
                       weight_check_every=10, quiet=True)
    assert stats.status == "failed" and "bias" in stats.message and stats.message.startswith("step 10")


def test_devices_and_budget_validation():
    assert resolve_device("cpu") == "cpu"
    assert resolve_device("auto") == ("cuda" if torch.cuda.is_available() else "cpu")
    with pytest.raises(InputError, match=r"^train\.device 'tpu': unknown device \(cpu \| cuda \| auto\)$"):
        resolve_device("tpu")
    if not torch.cuda.is_available():
        with pytest.raises(InputError, match=r"^train\.device 'cuda': CUDA is not available on this machine"):
            resolve_device("cuda")
    model, step_fn, _ = regression()
    with pytest.raises(InputError, match=r"^train budget max_steps=0, max_seconds=\S+: both must be > 0$"):
        train_loop(model, torch.optim.SGD(model.parameters(), lr=0.1), step_fn, Budget(max_steps=0))


def test_grad_clip_bounds_the_gradient_the_optimizer_steps_with_not_other_modules_gradients():
    """The GAN trains G through the loop (its optimizer) while the module also holds D, whose grads the generator
    loss fills too: grad_clip is the norm of the stepped parameters' gradient, whatever else the module holds."""
    torch.manual_seed(0)
    g, d = torch.nn.Linear(4, 1), torch.nn.Linear(4, 1)
    opt = torch.optim.SGD(g.parameters(), lr=1.0)
    x = torch.randn(64, 4) * 10
    norms = []
    step = opt.step

    def recording_step(*args, **kwargs):
        norms.append(float(torch.cat([p.grad.flatten() for p in g.parameters()]).norm()))
        return step(*args, **kwargs)

    opt.step = recording_step
    train_loop(torch.nn.ModuleDict({"G": g, "D": d}), opt, lambda i: (g(x) ** 2).mean() + 100 * (d(x) ** 2).mean(),
               Budget(max_steps=1, max_seconds=1e9), grad_clip=1.0, quiet=True)
    assert norms == [pytest.approx(1.0, rel=1e-5)]  # G's own gradient is far above 1: clipped to 1, not below
