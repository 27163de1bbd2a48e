"""Marching-cubes extraction against analytic fields (sphere, box)."""

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import grid_points
from ddfbench.evaluate import extract
from ddfbench.evaluate.extract import banded_grid, field_to_mesh, sdf_to_mesh, udf_to_mesh

R0 = 0.4


def sphere_sdf(p):
    return np.linalg.norm(p, axis=1) - R0


def test_sphere_sdf_mesh_lies_on_sphere_with_outward_normals():
    mesh, info = sdf_to_mesh(sphere_sdf, 49, 0.6)
    assert not info["empty"] and info["field_evals"] == 49**3
    r = np.linalg.norm(mesh.vertices, axis=1)
    assert np.abs(r - R0).max() < 0.005
    assert mesh.is_watertight
    assert abs(mesh.volume - 4 / 3 * np.pi * R0**3) / (4 / 3 * np.pi * R0**3) < 0.01
    outward = np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles_center) > 0
    assert outward.all()


def test_box_sdf_mesh_spans_the_box():
    half = np.array([0.3, 0.2, 0.1])
    box = lambda p: np.max(np.abs(p) - half, axis=1)  # noqa: E731 (exact inside, a bound outside)
    mesh, _ = sdf_to_mesh(box, 61, 0.6)
    assert np.allclose(mesh.bounds[1], half, atol=0.01) and np.allclose(mesh.bounds[0], -half, atol=0.01)


def crossing_nodes(values, level=0.0):
    """Brute force: nodes with a 6-neighbour on the other side of the level."""
    above = values > level
    out = np.zeros(values.shape, bool)
    for ax in range(3):
        for shift in (1, -1):
            other = np.roll(above, shift, axis=ax)
            edge = np.ones(values.shape, bool)
            idx = [slice(None)] * 3
            idx[ax] = 0 if shift == 1 else -1
            edge[tuple(idx)] = False  # np.roll wraps around: no edge there
            out |= edge & (other != above)
    return out


@pytest.mark.parametrize("coarse", [4, 8])
def test_narrow_band_matches_dense_grid_and_evaluates_less(coarse):
    dense, n_dense, _ = banded_grid(sphere_sdf, 65, 0.6, 0.0, coarse=1)
    band, n_band, capped = banded_grid(sphere_sdf, 65, 0.6, 0.0, coarse=coarse)
    assert n_band < n_dense / 5 and not capped
    assert np.array_equal(np.sign(band), np.sign(dense))
    ends = crossing_nodes(dense)
    assert ends.sum() > 1000 and np.array_equal(band[ends], dense[ends])
    m1, _ = sdf_to_mesh(sphere_sdf, 65, 0.6)
    m2, _ = sdf_to_mesh(sphere_sdf, 65, 0.6, coarse=coarse)
    assert np.allclose(np.sort(m1.vertices, axis=0), np.sort(m2.vertices, axis=0))


def test_narrow_band_finds_a_feature_thinner_than_the_coarse_lattice():
    """A plate 0.03 thick (a quarter of the first lattice's spacing) between coarse nodes."""
    plate = lambda p: np.abs(p[:, 2] - 0.013) - 0.015  # noqa: E731 (exact distance, Lipschitz 1)
    dense, _, _ = banded_grid(plate, 97, 0.6, 0.0, coarse=1)
    band, _, _ = banded_grid(plate, 97, 0.6, 0.0, coarse=8)
    assert (dense < 0).any() and np.array_equal(np.sign(band), np.sign(dense))


def test_carry_hands_each_node_the_state_of_a_coarse_node_near_it():
    axis = np.linspace(-0.6, 0.6, 33, dtype=np.float32)
    step, calls = axis[1] - axis[0], []

    def field(p, parent):
        calls.append(parent is None)
        if parent is None:  # state: the coarse node's own coordinates, passed down unchanged
            return sphere_sdf(p), p.copy()
        assert np.isin(np.round(parent, 5), np.round(axis[::4], 5)).all()
        # nearest node of each lattice in turn: at most 2 + 1 steps per axis from the coarse node
        assert (np.abs(p - parent) <= 3 * step + 1e-6).all()
        return sphere_sdf(p), parent

    values, _, _ = banded_grid(field, 33, 0.6, 0.0, coarse=4, carry=True)
    assert calls[0] and not all(calls[1:]) and len(calls) > 1
    plain, _, _ = banded_grid(sphere_sdf, 33, 0.6, 0.0, coarse=4)
    assert np.array_equal(values, plain)


def test_udf_gives_two_shells_at_the_level():
    level = 0.02
    mesh, info = udf_to_mesh(lambda p: np.abs(sphere_sdf(p)), 61, 0.6, level, coarse=3)
    r = np.linalg.norm(mesh.vertices, axis=1)
    assert not info["empty"]
    assert np.abs(np.abs(r - R0) - level).max() < 0.004
    assert (r < R0).any() and (r > R0).any()
    # normals point away from the sphere surface on both shells
    c = mesh.triangles_center
    rc = np.linalg.norm(c, axis=1)
    away = np.einsum("ij,ij->i", mesh.face_normals, c) * np.sign(rc - R0) > 0
    assert away[mesh.area_faces > 1e-9].all()


def test_torch_field_and_batches():
    fn = lambda p: torch.from_numpy(sphere_sdf(p))  # noqa: E731
    m1, _ = sdf_to_mesh(fn, 33, 0.6, batch=1000)
    m2, _ = sdf_to_mesh(sphere_sdf, 33, 0.6)
    assert np.allclose(m1.vertices, m2.vertices)


@pytest.mark.parametrize(
    "field",
    [lambda p: np.ones(len(p)), lambda p: -np.ones(len(p)), lambda p: np.full(len(p), np.nan),
     lambda p: np.full(len(p), np.inf), lambda p: np.zeros(len(p))],
)
def test_fields_without_a_crossing_give_an_empty_flagged_mesh(field):
    mesh, info = sdf_to_mesh(field, 17, 0.6)
    assert info["empty"] and info["reason"] and len(mesh.faces) == 0
    mesh, info = udf_to_mesh(lambda p: np.abs(field(p)), 17, 0.6, 0.01, coarse=4)
    assert info["empty"] and len(mesh.faces) == 0


def test_udf_with_inf_far_away_still_meshes():
    def udf(p):
        d = np.abs(sphere_sdf(p))
        return np.where(d > 0.1, np.inf, d)  # nothing in sight far from the surface

    mesh, info = udf_to_mesh(udf, 41, 0.6, 0.02)
    r = np.linalg.norm(mesh.vertices, axis=1)
    assert not info["empty"] and np.abs(np.abs(r - R0) - 0.02).max() < 0.005


def test_nan_values_are_counted():
    def field(p):
        v = sphere_sdf(p)
        v[np.linalg.norm(p, axis=1) > 0.55] = np.nan
        return v

    mesh, info = sdf_to_mesh(field, 33, 0.6)
    assert info["nonfinite"] > 0 and not info["empty"]
    assert np.abs(np.linalg.norm(mesh.vertices, axis=1) - R0).max() < 0.01


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_infinite_cells_alone_across_the_level_mesh_as_their_pocket(sign):
    """A diverged network: every finite value far on one side of the level (-10: inside), NaN (or -inf) in a ball
    of radius 0.3. The ball is meshed as the far side, as marching cubes sees it; it once raised."""
    p = grid_points(33, 0.6).reshape(33, 33, 33, 3)
    values = np.full((33, 33, 33), -10.0 * sign, np.float32)
    values[np.linalg.norm(p, axis=-1) < 0.3] = np.nan if sign > 0 else -np.inf
    mesh, info = field_to_mesh(values, 0.6, 0.0)
    r = np.linalg.norm(mesh.vertices, axis=1)
    assert not info["empty"] and info["nonfinite"] == (np.isnan(values).sum())
    assert 0.25 < r.min() and r.max() < 0.3 + 0.6 / 32  # the pocket's wall, between its nodes and the next ones


@settings(max_examples=300, deadline=None)
@given(st.lists(st.one_of(st.floats(-50, 50, width=32), st.sampled_from([np.inf, -np.inf, np.nan])),
                min_size=8, max_size=8), st.floats(-5, 5, width=32))
def test_a_field_marching_cubes_took_before_is_clipped_as_before(cells, level):
    """The bounds for infinite cells moved only where they lay on the wrong side of the level (marching cubes
    raised): every other field gets the bounds of the float32 arithmetic it always had, to the bit."""
    values = np.asarray(cells, np.float32).reshape(2, 2, 2)
    values = np.where(np.isnan(values), np.inf, values)
    finite = values[np.isfinite(values)]
    if finite.size == 0 or not values.min() < level < values.max():
        return
    span = float(finite.max() - finite.min()) + abs(level) + 1.0
    before = np.clip(values, finite.min() - span, finite.max() + span)  # 4d2b6f9's bounds
    if not before.min() <= level <= before.max():  # marching cubes refused it: the case that changed
        return
    seen, real = [], extract.measure.marching_cubes

    def capture(volume, **kwargs):
        seen.append(volume.copy())
        return real(volume, **kwargs)

    extract.measure.marching_cubes = capture
    try:
        field_to_mesh(values, 0.6, level)
    finally:
        extract.measure.marching_cubes = real
    assert np.array_equal(seen[0], before)


def test_bad_arguments_raise_input_errors():
    with pytest.raises(InputError, match=r"^udf level 0\.0: must be > 0 "):
        udf_to_mesh(sphere_sdf, 17, 0.6, 0.0)
    with pytest.raises(InputError, match=r"^mesh resolution 1: must be at least 2$"):
        grid_points(1, 0.6)
    with pytest.raises(InputError, match=r"^field grid of shape \(4, 4, 5\): must be a cube \(R, R, R\)$"):
        field_to_mesh(np.zeros((4, 4, 5)), 0.6, 0.0)


def test_a_band_that_would_cover_the_grid_is_capped_and_flagged():
    """A field near its level everywhere (an untrained net) must not cost a dense grid."""
    flat = lambda p: np.full(len(p), 0.02, np.float32) + 0.001 * p[:, 0]  # noqa: E731 - |slope| << band
    values, evals, capped = banded_grid(flat, 65, 0.6, 0.0, coarse=4, max_slices=5)
    first = 17**3  # the coarse lattice: every 4th node of 65
    assert capped and first <= evals <= first + 5 * 65**2
    assert np.isfinite(values).all()
    mesh, info = udf_to_mesh(flat, 65, 0.6, 0.0205, coarse=4)
    assert info["capped"] and info["field_evals"] <= first + extract.MAX_BAND_SLICES * 65**2 < 65**3 / 2
    _, sphere_info = udf_to_mesh(lambda p: np.abs(sphere_sdf(p)), 65, 0.6, 0.01, coarse=4)
    assert not sphere_info["capped"]
