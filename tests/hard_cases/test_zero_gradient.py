"""Case 10: zero-gradient points of neural fields.

Promise: where a neural field's gradient vanishes at a hit, its normal is flagged invalid
(Hits.normal_valid False) and is still finite; every valid normal is unit length and faces the ray;
the counting layer replaces an invalid normal by -direction, so no image of any preset holds NaN.
Fields: a neural_sdf (relu, no embedding) whose zero level is a flat plateau, f = relu(z) - relu(-z - 0.1)
(0 on -0.1 <= z <= 0, gradient exactly 0 there), and a ddf whose weights are all zero (constant
distance 0.3 and "hit" everywhere: zero gradient for every ray).
"""

import numpy as np
import pytest
import torch

from ddfbench.models import load_family
from ddfbench.render import parse_scene, plan_passes, render
from tests.hard_cases.conftest import unit


def plateau_neural_sdf():
    rep = load_family("neural_sdf")({"n_harmonics": 0, "width": 2, "depth": 1, "activation": "relu",
                                     "geometric_init": False})
    with torch.no_grad():
        rep.net.hidden[0].weight.copy_(torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]))
        rep.net.hidden[0].bias.copy_(torch.tensor([0.0, -0.1]))
        rep.net.out.weight.copy_(torch.tensor([[1.0, -1.0]]))
        rep.net.out.bias.zero_()
    return rep


def flat_ddf():
    rep = load_family("ddf")({"width": 8, "depth": 1, "param": "point", "pos_freqs": 0, "dir_freqs": 0})
    with torch.no_grad():
        for p in rep.net.parameters():
            p.zero_()
        rep.net.out.bias.copy_(torch.tensor([0.3, 5.0]))  # distance 0.3, visibility logit +5
    return rep


FIELDS = {"neural_sdf plateau": plateau_neural_sdf, "ddf constant": flat_ddf}


def test_plateau_field_is_what_it_says():
    rep = plateau_neural_sdf()
    z = np.linspace(-0.3, 0.3, 61, dtype=np.float32)
    p = np.c_[np.zeros((61, 2), np.float32), z]
    assert np.allclose(rep.sdf(p), np.where(z > 0, z, np.where(z < -0.1, z + 0.1, 0.0)), atol=1e-7)


@pytest.mark.parametrize("name", list(FIELDS))
def test_normals_are_unit_or_flagged(name):
    rep = FIELDS[name]()
    rng = np.random.default_rng(0)
    o = unit(rng.normal(size=(3000, 3))) * 1.5
    d = unit(rng.uniform(-0.4, 0.4, (3000, 3)) - o)
    hits = rep.intersect(o, d)
    assert hits.hit.sum() > 500
    assert np.isfinite(hits.normal).all() and not np.isnan(hits.t).any()
    valid = hits.normal_valid & hits.hit
    invalid = hits.hit & ~hits.normal_valid
    assert invalid.sum() > 0, "the field should produce zero-gradient hits"
    assert np.allclose(np.linalg.norm(hits.normal[valid], axis=1), 1.0, atol=1e-5)
    assert np.all(np.einsum("ij,ij->i", hits.normal[valid], d[valid]) <= 0)


SCENE = {"name": "zero_gradient", "outputs": ["depth", "mask", "normal", "shaded", "shadow", "path"],
         "width": 16, "height": 16, "spp": 2, "max_depth": 3, "environment": 0.5,
         "cameras": {"n": 3, "radius": 2.0, "elevation_deg": 40.0},
         "lights": [{"type": "directional", "direction": [-0.3, -1.0, -0.2], "intensity": 2.0},
                    {"type": "point", "position": [0.5, 1.0, 0.5], "intensity": 1.0}],
         "timing": {"repeats": 1, "warmup": 0}}


@pytest.mark.parametrize("name", list(FIELDS))
def test_no_nan_in_any_image(name):
    scene = parse_scene(SCENE)
    frames, counts = render(FIELDS[name](), scene, plan_passes(scene), seed=0)
    assert frames.mask.any()
    arrays = {"depth": frames.depth[frames.mask], "normal": frames.normal, "shadow": frames.shadow, **frames.images}
    for key, a in arrays.items():
        assert np.isfinite(a).all(), f"{name}: {key} holds non-finite values"
    n = frames.normal[frames.mask]
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)
    assert counts["bounce_rays"] > 0 and counts["shadow_rays"] > 0
