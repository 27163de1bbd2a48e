"""Shared fixtures: small normalized meshes and a seeded generator."""

import numpy as np
import pytest
import torch

from ddfbench.truth.shapes import load_shape

torch.set_num_threads(1)


@pytest.fixture(scope="session")
def bunny():
    return load_shape({"name": "bunny"})


@pytest.fixture(scope="session")
def sphere():
    return load_shape({"name": "sphere"})


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def random_rays(rng, n, half=0.6):
    """n rays: origins uniform in the box of half-side `half`, unit directions uniform on the sphere."""
    o = rng.uniform(-half, half, (n, 3))
    d = rng.normal(size=(n, 3))
    return o, d / np.linalg.norm(d, axis=1, keepdims=True)
