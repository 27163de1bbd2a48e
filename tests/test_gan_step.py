"""`python -m ddfbench.bench.gan_step`: the thesis GAN's whole training step, timed per pool and heap setting."""

import re

import pytest
import torch

from ddfbench.bench import gan_step as module
from ddfbench.bench.gan_step import WARM_STEPS, gan_step, main, step_seconds


def test_step_seconds_times_only_the_steps_after_the_warm_ones(monkeypatch):
    calls, clock = [], iter([10.0, 13.0])
    monkeypatch.setattr(module.time, "perf_counter", lambda: next(clock))
    assert step_seconds(lambda: calls.append(1), 4) == pytest.approx(0.75)
    assert len(calls) == WARM_STEPS + 4


@pytest.mark.parametrize("pools", ["stride1", "torch"])
def test_a_step_updates_both_networks(pools, monkeypatch):
    monkeypatch.setattr(module, "BATCH", 64)  # the thesis' 1024 costs ~1 s a step; the update is the same code
    made = []
    for name in ("generator", "discriminator"):
        build = getattr(module, name)
        monkeypatch.setattr(module, name, lambda *a, _b=build: made.append(_b(*a)) or made[-1])
    step = gan_step(pools, n_points=4096)
    before = [[p.detach().clone() for p in net.parameters()] for net in made]
    step()
    for net, old in zip(made, before):
        assert (type(net.pool) is torch.nn.MaxPool1d) == (pools == "torch")
        assert any(not torch.equal(p, q) for p, q in zip(net.parameters(), old))


@pytest.mark.slow
def test_the_command_prints_its_cell(capsys, monkeypatch):
    monkeypatch.setattr(module, "BATCH", 64)
    main(["1", "1", "torch", "default"])
    assert re.fullmatch(r"torch default 1 \d+\.\d{3}\n", capsys.readouterr().out)
