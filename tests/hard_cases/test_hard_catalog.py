"""The `hard/...` shapes themselves: sizes as documented, bad parameters rejected, served by load_shape."""

import numpy as np
import pytest

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import grid_axis
from ddfbench.truth.shapes import HARD_CASES, SHAPE_BUILDERS, load_shape
from tests.hard_cases.conftest import hard_shape

SMALL = {"hard/torus_grid": {"segments": 40}, "hard/moved": {"base": "cube", "offset": 10.0}}


@pytest.mark.parametrize("name", HARD_CASES)
def test_every_hard_shape_loads(name):
    shape = hard_shape(name, **SMALL.get(name, {}))
    assert np.ptp(shape.mesh.vertices, axis=0).max() == pytest.approx(1.0)


def test_thin_plate_in_grid_voxels():
    axis = grid_axis(65, 0.6)
    h = float(axis[1] - axis[0])
    plate = hard_shape("hard/thin_plate", voxels=0.5, resolution=65, domain=0.6)
    assert np.ptp(plate.mesh.vertices[:, 2]) == pytest.approx(h / 2) and plate.watertight


def test_plate_pair_gap():
    pair = hard_shape("hard/plate_pair", gap=1e-3, thickness=0.02)
    z = np.unique(np.round(pair.mesh.vertices[:, 2], 9))
    assert np.allclose(np.diff(z), [0.02, 1e-3, 0.02]) and pair.watertight


@pytest.mark.parametrize("name,params", [("hard/thin_plate", {"thickness": 0.1, "voxels": 1}), ("hard/thin_plate", {"thickness": 2.0}),
                                         ("hard/plate_pair", {"gap": 0.0}), ("hard/torus_grid", {"segments": 3}),
                                         ("hard/moved", {"scale": 0.0})])
def test_bad_parameters_are_input_errors(name, params):
    with pytest.raises(InputError, match=name):
        SHAPE_BUILDERS[name](**params)


def test_load_shape_serves_hard_names():
    """load_shape builds names starting with "hard/" from ddfbench.truth.shapes.SHAPE_BUILDERS, validated like any mesh."""
    shape = load_shape({"name": "hard/plate_pair", "params": {"gap": 1e-3}})
    assert np.array_equal(shape.mesh.vertices, hard_shape("hard/plate_pair", gap=1e-3).mesh.vertices)
