"""Shared fixtures: small normalized meshes and a seeded generator."""

import os
import tempfile

import numpy as np
import pytest
import torch

from ddfbench.truth.shapes import load_shape

torch.set_num_threads(1)

# hypothesis keeps its example database and caches in ./.hypothesis/ unless told otherwise: keep them out of the
# checkout, in one folder of the temp dir (failing examples still replay on the next run); the profiles stay as they
# are (a settings profile with database=None would not do: the constants cache is written all the same).
os.environ.setdefault("HYPOTHESIS_STORAGE_DIRECTORY",
                      os.path.join(tempfile.gettempdir(), f"ddfbench-hypothesis-{os.getuid()}"))


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


def rebuilt_differences(folder, into):
    """The text files of a re-measurement folder that its rebuild from the measured rows saved there (into `into`)
    writes otherwise, byte for byte, or does not write; [] when every one comes back the same."""
    from ddfbench.report import measured, regenerate

    measured.rebuild(str(folder), str(into))
    return regenerate.differences(str(folder), str(into), whole=True)


def pytest_collection_modifyitems(session, config, items):
    """Files with the most slow-marked tests first, each file's tests in their own order: pytest-xdist's
    --dist loadfile hands whole files to whichever worker is free, so the longest files starting first keeps one
    worker from running a long file alone at the end (longest-first scheduling, by the `slow` marker count)."""
    slow: dict[str, int] = {}
    for item in items:
        slow[item.nodeid.split("::")[0]] = slow.get(item.nodeid.split("::")[0], 0) + bool(item.get_closest_marker("slow"))
    order = {path: rank for rank, path in enumerate(sorted(slow, key=lambda p: -slow[p]))}  # stable: ties keep order
    items.sort(key=lambda item: order[item.nodeid.split("::")[0]])
