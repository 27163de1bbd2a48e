"""neural_sdf's eikonal term: evaluated on points uniform over the whole field box, and it makes |grad f| = 1 there."""

import numpy as np
import torch

from ddfbench.core.representation import Budget, FitData
from ddfbench.models import load_family, neural_sdf
from ddfbench.sampling.oracle_sdf import oracle_sdf_samples
from ddfbench.truth.oracle import Oracle
from ddfbench.truth.shapes import load_shape

DOMAIN = 0.6
NET = {"width": 32, "depth": 2, "n_harmonics": 2, "batch": 1024, "lr": 3e-3, "lr_schedule": "constant"}


def fit(cfg, steps, monkeypatch=None, seen=None):
    shape = load_shape({"name": "sphere"})
    oracle = Oracle(shape.mesh)
    samples = oracle_sdf_samples(shape.mesh, oracle, 4000, seed=0)
    if monkeypatch is not None:
        real = neural_sdf.eikonal_residual
        monkeypatch.setattr(neural_sdf, "eikonal_residual", lambda net, p: seen.append(p.detach().clone()) or real(net, p))
    rep = load_family("neural_sdf")(dict(NET, **cfg), DOMAIN)
    torch.set_num_threads(1)
    stats = rep.fit(FitData(samples, shape.mesh, oracle), Budget(max_steps=steps, max_seconds=120))
    assert stats.status == "ok"
    return rep


def test_eikonal_points_fill_the_box_not_the_samples(monkeypatch):
    seen = []
    fit({"w_eikonal": 0.1}, 20, monkeypatch, seen)
    p = torch.cat(seen).numpy()
    assert len(seen) == 20 and np.abs(p).max() <= DOMAIN
    # uniform in the box: each coordinate's quartiles near -0.3, 0, 0.3; the sphere's samples hug |x| = 0.5
    np.testing.assert_allclose(np.percentile(p, [25, 50, 75], axis=0), [[-0.3] * 3, [0] * 3, [0.3] * 3], atol=0.03)


def residual_on_box(rep, n=4000):
    p = (torch.rand(n, 3, generator=torch.Generator().manual_seed(5)) * 2 - 1) * DOMAIN
    return float(neural_sdf.eikonal_residual(rep.net, p).detach())


def test_eikonal_term_makes_the_gradient_unit_everywhere():
    """Trained on the eikonal term alone, the field's slope is 1 over the box (it starts far from it)."""
    torch.manual_seed(0)
    untrained = load_family("neural_sdf")(dict(NET, geometric_init=False), DOMAIN)
    trained = fit({"w_sdf": 0.0, "w_eikonal": 1.0, "geometric_init": False}, 300)
    assert residual_on_box(untrained) > 0.5 and residual_on_box(trained) < 0.05
