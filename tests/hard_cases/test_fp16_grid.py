"""Case 14: float16 grids: values beyond the float16 range (|v| > 65504) are clamped, no inf in lookups.

Promise: a grid_sdf stored as float16 holds only finite values, whatever its build produced (here an
oracle whose distances are scaled by 1e6, and an artifact file with inf in it): values beyond the range
become +-65504 with their sign kept, in-range values round to float16 as usual; sdf lookups, rays and
normals stay finite after fit and after save/load.
"""

import numpy as np
import pytest

from ddfbench.core.representation import Budget, FitData
from ddfbench.models import load_family
from ddfbench.truth.oracle import Oracle
from tests.hard_cases.conftest import unit

FP16_MAX = float(np.finfo(np.float16).max)  # 65504


class ScaledOracle:
    """The sphere's oracle with every distance multiplied by `scale` (same zero level, huge values)."""

    def __init__(self, mesh, scale):
        self.inner, self.scale = Oracle(mesh), scale

    def signed_distance(self, p):
        return self.inner.signed_distance(p) * self.scale


@pytest.fixture(scope="module")
def huge_grid(sphere):
    rep = load_family("grid_sdf")({"resolution": 24, "build": "exact", "dtype": "float16"})
    rep.fit(FitData(None, sphere.mesh, ScaledOracle(sphere.mesh, 1e6)), Budget())
    exact = ScaledOracle(sphere.mesh, 1e6).signed_distance(
        np.stack(np.meshgrid(*[np.linspace(-0.6, 0.6, 24)] * 3, indexing="ij"), -1).reshape(-1, 3)).reshape(24, 24, 24)
    return rep, exact


def lookups_are_finite(rep):
    rng = np.random.default_rng(0)
    assert np.isfinite(rep.sdf(rng.uniform(-0.8, 0.8, (5000, 3)))).all()
    o = unit(rng.normal(size=(500, 3))) * 1.5
    hits = rep.intersect(o, unit(rng.uniform(-0.3, 0.3, (500, 3)) - o))
    assert not np.isnan(hits.t).any() and np.isfinite(hits.normal).all()
    return hits


def test_values_beyond_the_range_are_clamped(huge_grid):
    """A float16 grid holds every value finite: |values| beyond 65504 are stored as +-65504 (a plain
    cast would store +-inf, and trilinear lookups between inf nodes would give NaN), the rest as the
    float16 of the exact value. Loading goes through the same clamp, so an artifact holding inf is read finite."""
    rep, exact = huge_grid
    grid = np.asarray(rep.grid)
    assert grid.dtype == np.float16 and np.isfinite(grid).all()
    beyond = np.abs(exact) > FP16_MAX
    assert beyond.any() and np.all(grid[beyond] == np.sign(exact[beyond]) * FP16_MAX)
    assert np.array_equal(grid[~beyond], exact[~beyond].astype(np.float16))


def test_lookups_and_rays_are_finite(huge_grid):
    rep, _ = huge_grid
    # a field scaled by 1e6 is no distance bound, so sphere tracing may step past the surface: only
    # finiteness is promised here
    lookups_are_finite(rep)


def test_saved_and_loaded_grid_stays_finite(huge_grid, tmp_path):
    rep, _ = huge_grid
    again = load_family("grid_sdf").load(rep.save(str(tmp_path / "model")))
    assert np.isfinite(np.asarray(again.grid)).all()
    lookups_are_finite(again)


def test_artifact_with_inf_is_clamped_on_load(huge_grid, tmp_path):
    rep, _ = huge_grid
    path = rep.save(str(tmp_path / "model"))
    with np.load(path, allow_pickle=False) as z:
        header, grid = z["header"], z["sdf"].copy()
    grid[0, 0, :4] = [np.inf, -np.inf, np.inf, -np.inf]
    np.savez(path, sdf=grid, header=header)
    again = load_family("grid_sdf").load(path)
    assert np.isfinite(np.asarray(again.grid)).all()
    lookups_are_finite(again)
