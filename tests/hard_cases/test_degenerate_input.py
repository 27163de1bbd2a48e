"""Case 5: degenerate input: zero-area, duplicate and flipped faces, unreferenced vertices.

Promise: loading removes zero-area faces (an index repeated, or three collinear vertices up to
float64 rounding), duplicate faces (any vertex order) and unreferenced vertices, and says so,
with counts, in Shape.warnings (the record's shape.warnings); inconsistently wound faces are
reported too. Nothing downstream sees a NaN normal, and sampling never draws a point from a
zero-area face. A mesh whose every face has zero area is a one-line InputError.
"""

import numpy as np
import pytest
import trimesh

from ddfbench.core.errors import InputError
from ddfbench.evaluate.metrics import sample_surface
from ddfbench.truth.catalog import dirty_sphere
from ddfbench.truth.oracle import Oracle
from tests.hard_cases.conftest import assert_well_formed, hard_shape, has_warp, unit

DEFECTS = dict(zero_area=3, duplicate=4, flipped=5, unreferenced=6)


def warning_with(shape, *words):
    found = [w for w in shape.warnings if all(word in w for word in words)]
    assert found, f"no warning mentions {words}: {shape.warnings}"
    return found[0]


def test_duplicate_faces_removed_and_reported():
    shape = hard_shape("hard/dirty_sphere", **{**DEFECTS, "zero_area": 0, "flipped": 0})
    assert warning_with(shape, "duplicate") == "removed 4 duplicate faces"
    assert len(shape.mesh.faces) == 320 and shape.watertight


def test_unreferenced_vertices_removed_and_do_not_move_the_box():
    shape = hard_shape("hard/dirty_sphere", **{**DEFECTS, "zero_area": 0, "flipped": 0})
    assert warning_with(shape, "unreferenced") == "removed 6 unreferenced vertices"
    assert len(shape.mesh.vertices) == 162  # the icosphere's own, none of the far-away ones
    assert np.allclose(np.ptp(shape.mesh.vertices, axis=0).max(), 1.0)
    assert np.abs(shape.mesh.vertices).max() <= 0.5 + 1e-12


def test_zero_area_faces_removed_and_reported():
    """validate removes zero-area faces, both those repeating a vertex index and those on three
    collinear vertices (twice-area ~1e-17 after float64 rounding), says how many, and the sphere is
    watertight again (a sliver left in would open it and give a zero face normal to a ray hitting it)."""
    shape = hard_shape("hard/dirty_sphere", **{**DEFECTS, "flipped": 0})
    assert warning_with(shape, "zero-area") == "removed 3 zero-area faces"
    assert len(shape.mesh.faces) == 320 and shape.watertight


def test_flipped_faces_reported():
    """validate re-winds faces wound against their neighbours and its warning says how many (5)."""
    shape = hard_shape("hard/dirty_sphere", **{**DEFECTS, "zero_area": 0, "duplicate": 0, "unreferenced": 0})
    text = " ".join(shape.warnings)
    assert ("wound" in text or "winding" in text or "flipped" in text) and "5" in text, shape.warnings
    raw = dirty_sphere(**{**DEFECTS, "zero_area": 0, "duplicate": 0, "unreferenced": 0})
    assert not raw.is_winding_consistent  # the 5 flipped faces are there before validation ...
    assert shape.mesh.is_winding_consistent and shape.mesh.volume > 0  # ... and re-wound outward after it


def test_warnings_reach_the_record_summary():
    shape = hard_shape("hard/dirty_sphere", **DEFECTS)
    summary = shape.summary()
    assert summary["warnings"] == shape.warnings and len(summary["warnings"]) >= 3


def test_no_nan_normals_anywhere():
    raw = dirty_sphere(**DEFECTS)
    assert np.isfinite(raw.face_normals).all()  # trimesh on the raw, defective mesh
    shape = hard_shape("hard/dirty_sphere", **DEFECTS)
    assert np.allclose(np.linalg.norm(shape.mesh.face_normals, axis=1), 1.0)
    rng = np.random.default_rng(0)
    o = rng.uniform(-0.6, 0.6, (20000, 3))
    d = unit(rng.normal(size=(20000, 3)))
    for backend in ("open3d", "embree") + (("warp",) if has_warp() else ()):
        t, tri, n = Oracle(shape.mesh, backend).first_hit(o, d)
        assert_well_formed(t, tri >= 0, n)


def test_zero_area_faces_never_sampled():
    """Even on the raw mesh (before validation), area-weighted sampling never picks a zero-area face."""
    raw = dirty_sphere(**DEFECTS)
    points, normals = sample_surface(raw, 50000, seed=1)
    assert np.isfinite(points).all()
    assert np.allclose(np.linalg.norm(normals, axis=1), 1.0)
    assert np.abs(np.linalg.norm(points, axis=1) - 0.5).max() < 0.02  # on the sphere, not at the far vertices


def test_all_faces_degenerate_is_a_clear_error():
    v = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]])
    mesh = trimesh.Trimesh(v, [[0, 1, 2], [1, 1, 3], [0, 2, 3]], process=False)
    from ddfbench.truth.shapes import validate

    with pytest.raises(InputError) as info:
        validate(mesh, "shape line.obj")
    assert "line.obj" in str(info.value) and "\n" not in str(info.value)
