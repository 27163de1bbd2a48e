"""Case 11: unsigned fields with no zero crossing, constant fields and non-finite fields in extraction.

Promise: sdf_to_mesh / udf_to_mesh / field_to_mesh never call marching cubes on a field that does not
cross the level (an unsigned field at level 0, a constant, all inf or NaN): they return an empty mesh
(0 vertices, 0 faces) with info["empty"] True and a reason; an unsigned level <= 0 is a one-line
InputError; a field that crosses still gives a mesh.
"""

import numpy as np
import pytest

from ddfbench.core.errors import InputError
from ddfbench.evaluate import extract


@pytest.fixture
def no_marching_cubes(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("marching cubes was called on a field without a crossing")

    monkeypatch.setattr(extract.measure, "marching_cubes", refuse)


def udf(p):
    return np.abs(np.linalg.norm(p, axis=1) - 0.3)


FIELDS = {
    "unsigned at level 0": lambda p: udf(p),
    "constant zero": lambda p: np.zeros(len(p)),
    "constant positive": lambda p: np.full(len(p), 0.2),
    "all inf": lambda p: np.full(len(p), np.inf),
    "all nan": lambda p: np.full(len(p), np.nan),
}


@pytest.mark.parametrize("name", list(FIELDS))
def test_sdf_extraction_of_fields_without_a_crossing_is_empty(no_marching_cubes, name):
    mesh, info = extract.sdf_to_mesh(FIELDS[name], 24, 0.6)
    assert len(mesh.vertices) == 0 and len(mesh.faces) == 0
    assert info["empty"] is True and info["reason"]


@pytest.mark.parametrize("coarse", [1, 4])
def test_udf_extraction_of_a_constant_is_empty(no_marching_cubes, coarse):
    mesh, info = extract.udf_to_mesh(lambda p: np.full(len(p), 0.3), 24, 0.6, level=0.01, coarse=coarse)
    assert len(mesh.faces) == 0 and info["empty"] is True


def test_unsigned_level_zero_is_a_clear_error():
    with pytest.raises(InputError, match="level"):
        extract.udf_to_mesh(udf, 24, 0.6, level=0.0)


def test_a_crossing_field_still_gives_a_mesh():
    mesh, info = extract.udf_to_mesh(udf, 32, 0.6, level=0.02)
    assert info["empty"] is False and len(mesh.faces) > 0
    assert np.abs(udf(np.asarray(mesh.vertices)) - 0.02).max() < 0.01
