"""Case 4: the same shape far from the origin and at extreme scales.

Promise: normalization runs in float64, so the cow translated by 1e3, 1e5, 1e7 and scaled by
1e-3 or 1e3 (and 1e-3 at 1e7 together) normalizes to the same mesh within 1e-6 of the unit cube
and gives the same geometry metrics against a fixed reconstruction within 1e-3 relative (f-scores
within 1e-3 absolute: 4 of 4000 points). Scaled by 1e-3 at 1e7, float64 keeps only ~2e-6 of the
extent (its spacing there is 1.9e-9), and the metrics agree within 1e-2 relative.
Where the offset leaves fewer than ~12 significant digits for the shape's extent, loading stops
with a one-line InputError instead of returning a quantized shape.
"""

import numpy as np
import pytest

from ddfbench.core.errors import InputError
from ddfbench.evaluate.metrics import geometry_metrics
from ddfbench.models.mesh import decimate
from ddfbench.truth.shapes import load_shape
from tests.hard_cases.conftest import hard_shape

RADII = [0.005, 0.01, 0.02]


@pytest.fixture(scope="module")
def cow():
    return load_shape({"name": "cow"})


@pytest.fixture(scope="module")
def reconstruction(cow):
    return decimate(cow.mesh, 300)


@pytest.fixture(scope="module")
def reference_metrics(cow, reconstruction):
    return geometry_metrics(cow.mesh, reconstruction, 4000, RADII, seed=5)


def flat(metrics):
    out = {}
    for k, v in metrics.items():
        if isinstance(v, dict):
            out.update({f"{k}.{kk}": vv for kk, vv in flat(v).items()})
        elif isinstance(v, float):
            out[k] = v
    return out


@pytest.mark.parametrize("offset,scale,rel", [(1e3, 1, 1e-3), (1e5, 1, 1e-3), (1e7, 1, 1e-3), (0, 1e-3, 1e-3),
                                              (0, 1e3, 1e-3), (1e7, 1e-3, 1e-2), (1e10, 1, 1e-2)])
def test_normalization_undoes_offset_and_scale(cow, reconstruction, reference_metrics, offset, scale, rel):
    moved = hard_shape("hard/moved", base="cow", offset=offset, scale=scale)
    assert moved.warnings == []
    assert np.abs(moved.mesh.vertices - cow.mesh.vertices).max() < 1e-6
    assert moved.transform["scale"] == pytest.approx(1.0 / scale, rel=1e-6)
    got = flat(geometry_metrics(moved.mesh, reconstruction, 4000, RADII, seed=5))
    ref = flat(reference_metrics)
    assert got.keys() == ref.keys()
    for k in ref:
        assert np.isfinite(got[k])
        # f-scores count points inside a radius: a 1e-6 shift may move a point or two across it
        tol = dict(abs=1e-3) if "fscore" in k else dict(rel=rel, abs=1e-9)
        assert got[k] == pytest.approx(ref[k], **tol), k


@pytest.mark.parametrize("offset,scale", [(1e10, 1e-3), (1e13, 1e-3), (1e11, 1.0)])
def test_offset_beyond_float64_precision_is_a_clear_error(offset, scale):
    """At 1e13 the float64 spacing (2e-3) exceeds the 1e-3 extent and every face collapses: the error
    names the cause (precision: extent too small for its offset), not its symptom (zero-area faces). At 1e11 a
    unit shape would still mesh, but rounded by 7.6e-6 of its extent: past the 1e-6 promised, so an error too."""
    with pytest.raises(InputError, match="precision lost: its coordinates round by more than 1e-6"):
        hard_shape("hard/moved", base="cow", offset=offset, scale=scale)
