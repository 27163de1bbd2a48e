"""Case 9: DDF training batches in which every ray misses, and a DDF that predicts no hit anywhere.

Promise: the DDF loss stays finite when a batch holds no hit (the distance term averages over hits
only and is 0 without one; the visibility term is still defined), for the engineered preset (l1 +
visibility head) and the paper's clamp loss; a fit on samples that all miss ends "ok" with a finite
loss curve. A DDF whose visibility says "no hit" everywhere answers every ray MISS (t = inf, zero
normal), gives an empty mesh under either mesh field (signed, udf), and the metrics give the
documented penalty with empty_reconstruction = True.
"""

import numpy as np
import pytest
import torch

from ddfbench.core.representation import Budget, FitData, RayStatus
from ddfbench.evaluate.metrics import geometry_metrics
from ddfbench.models import load_family
from ddfbench.sampling.samples import Samples
from ddfbench.truth.oracle import Oracle
from tests.hard_cases.conftest import assert_well_formed, unit

SMALL = {"width": 32, "depth": 2, "pos_freqs": 2, "dir_freqs": 1, "batch": 64, "eval_batch": 8192,
         "udf_directions": 8, "mesh_directions": 8}
PRESETS = {"engineered": {}, "paper clamp": {"loss": "clamp", "visibility": "clamp", "delta": 0.5},
           "clamp on misses": {"loss": "clamp_misses", "visibility": "clamp", "delta": 0.5}}
D = 2 * 0.6 * np.sqrt(3.0)
RADII = [0.005, 0.01, 0.02]


def ray_samples(oracle, n, seed, hit_share=None):
    """Random rays in the box labelled by the oracle; hit_share=0 keeps only rays that miss."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-0.6, 0.6, (4 * n, 3))
    d = unit(rng.normal(size=(4 * n, 3)))
    t = oracle.first_hit(x, d)[0]
    keep = np.flatnonzero(np.isinf(t))[:n] if hit_share == 0 else np.arange(n)
    return Samples(x=x[keep].astype(np.float32), d=d[keep].astype(np.float32), t=t[keep], hit=np.isfinite(t[keep]))


@pytest.fixture(scope="module")
def sphere_oracle(sphere):
    return sphere.mesh, Oracle(sphere.mesh)


@pytest.mark.parametrize("preset", list(PRESETS))
def test_all_miss_batches_have_a_finite_loss(sphere_oracle, preset):
    """A batch of 64 from samples where 1 ray in 200 hits: about 3 batches in 4 hold no hit at all."""
    mesh, oracle = sphere_oracle
    s = ray_samples(oracle, 5000, seed=1, hit_share=0)
    s.hit[::200], s.t[::200] = True, 0.3  # a few hits, so the fit has something to learn
    rep = load_family("ddf")({**SMALL, **PRESETS[preset]})
    stats = rep.fit(FitData(s, mesh, oracle), Budget(max_steps=200, max_seconds=20, n_probes=0))
    assert stats.status == "ok" and stats.steps == 200, stats.message
    assert all(np.isfinite(loss) for _, _, loss in stats.loss_curve)


@pytest.mark.parametrize("preset", list(PRESETS))
def test_fit_on_samples_that_all_miss(sphere_oracle, preset):
    mesh, oracle = sphere_oracle
    s = ray_samples(oracle, 4000, seed=2, hit_share=0)
    assert not s.hit.any()
    rep = load_family("ddf")({**SMALL, **PRESETS[preset]})
    stats = rep.fit(FitData(s, mesh, oracle), Budget(max_steps=150, max_seconds=20, n_probes=0))
    assert stats.status == "ok", stats.message
    assert all(np.isfinite(loss) for _, _, loss in stats.loss_curve)
    rng = np.random.default_rng(3)
    o = unit(rng.normal(size=(500, 3))) * 1.5
    hits = rep.intersect(o, unit(rng.uniform(-0.3, 0.3, (500, 3)) - o))
    assert_well_formed(hits.t, hits.hit, hits.normal)
    assert hits.hit.mean() < 0.05, "a DDF taught only misses should hardly ever hit"


def blind_ddf(mesh_field):
    """A DDF whose visibility head says 'no hit' everywhere (bias -100)."""
    rep = load_family("ddf")({**SMALL, "mesh_field": mesh_field})
    with torch.no_grad():
        rep.net.out.bias[1] = -100.0
    return rep


@pytest.mark.parametrize("mesh_field", ["signed", "udf"])
def test_no_hit_anywhere_gives_an_empty_mesh_and_the_penalty(sphere_oracle, mesh_field):
    mesh, _ = sphere_oracle
    rep = blind_ddf(mesh_field)
    rng = np.random.default_rng(4)
    o = rng.uniform(-1.0, 1.0, (2000, 3))
    hits = rep.intersect(o, unit(rng.normal(size=(2000, 3))))
    assert_well_formed(hits.t, hits.hit, hits.normal)
    assert not hits.hit.any() and np.all(hits.status == RayStatus.MISS)
    rec = rep.to_mesh(24)
    assert len(rec.vertices) == 0 and len(rec.faces) == 0
    m = geometry_metrics(mesh, rec, 2000, RADII, seed=0)
    assert m["empty_reconstruction"] is True
    assert m["chamfer_l2"] == pytest.approx(2 * D**2) and m["chamfer_l1"] == pytest.approx(D)
    assert all(v == 0.0 for v in m["fscore"].values())
