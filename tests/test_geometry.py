"""ddfbench.core.geometry: the one ray-box test (numpy and torch alike, the in-face case an interval),
the one pinhole camera, the one positional encoding."""

import math

import numpy as np
import pytest
import torch

from ddfbench.core.geometry import BOX_HALF, FourierFeatures, box_entry, pinhole_rays, ray_box
from ddfbench.sampling.directions import uniform_directions


def test_ray_box_matches_a_brute_force_march():
    rng = np.random.default_rng(0)
    o = rng.uniform(-1, 1, (200, 3))
    d = uniform_directions(rng, 200).astype(np.float64)
    t_in, t_out = ray_box(o, d, 0.5)
    s = np.linspace(-4, 4, 8001)
    inside = np.all(np.abs(o[:, None] + s[None, :, None] * d[:, None]) <= 0.5, axis=2)
    for i in range(200):
        if inside[i].any():
            assert abs(s[inside[i]].min() - t_in[i]) < 2e-3 and abs(s[inside[i]].max() - t_out[i]) < 2e-3
        else:
            assert t_in[i] > t_out[i]


@pytest.mark.parametrize("kind", ["numpy", "torch"])
def test_box_entry_from_t_zero_matches_a_brute_force_march(kind):
    """t_entry is the first t >= 0 inside the box (0 from inside), meets whether any is; float32 stays float32."""
    rng = np.random.default_rng(0)
    o = rng.uniform(-2, 2, (500, 3)).astype(np.float32)
    d = uniform_directions(rng, 500).astype(np.float32)
    d[:5] = [1, 0, 0]  # axis-parallel rays hit the slab-parallel case
    args = (o, d) if kind == "numpy" else (torch.from_numpy(o), torch.from_numpy(d))
    t_in, t_out, meets = (np.asarray(v) for v in box_entry(*args, 0.6))
    assert t_in.dtype == t_out.dtype == np.float32 and meets.dtype == bool
    ts = np.linspace(0, 5, 5001)
    inside = np.all(np.abs(o[:, None, :] + ts[None, :, None] * d[:, None, :]) <= 0.6, axis=2)
    clear = ~meets | (t_out - t_in > 2e-3)  # chords shorter than the marching step may slip through
    assert np.array_equal(meets[clear], inside.any(1)[clear])
    assert inside[:, 0].any() and (t_in[inside[:, 0]] == 0).all()  # origins inside the box enter at 0
    first = np.where(inside.any(1), ts[inside.argmax(1)], np.nan)
    assert np.allclose(t_in[inside.any(1)], first[inside.any(1)], atol=2e-3)


# rays with zero direction components: in a face, on an edge, inside, parallel outside a face
H = BOX_HALF
FLAT = [
    ((-1.0, 0.2, H), (1.0, 0.0, 0.0), (1 - H, 1 + H)),     # lies in the +z face
    ((-1.0, 0.2, -H), (1.0, 0.0, 0.0), (1 - H, 1 + H)),    # lies in the -z face
    ((0.1, -1.0, -H), (0.0, 1.0, 0.0), (1 - H, 1 + H)),    # lies in the -z face along y
    ((-1.0, H, -H), (1.0, 0.0, 0.0), (1 - H, 1 + H)),      # runs along an edge
    ((-1.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1 - H, 1 + H)),   # axis-parallel through the middle
    ((-1.0, 0.0, H + 1e-3), (1.0, 0.0, 0.0), None),        # parallel just outside the +z face
    ((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (-H, H)),           # from the centre
]


@pytest.mark.parametrize("origin,direction,interval", FLAT)
def test_flat_rays_in_a_face_meet_the_closed_box(origin, direction, interval):
    o, d = np.array([origin]), np.array([direction])
    for kind in ("numpy", "torch"):
        oo, dd = (o, d) if kind == "numpy" else (torch.tensor(o, dtype=torch.float32), torch.tensor(d, dtype=torch.float32))
        enter, leave = (np.asarray(v, np.float64)[0] for v in ray_box(oo, dd))
        assert not (np.isnan(enter) or np.isnan(leave)), kind
        if interval is None:
            assert enter > leave, kind
        else:
            assert (enter, leave) == pytest.approx(interval, abs=1e-6), kind


def test_numpy_and_torch_agree_on_random_rays():
    rng = np.random.default_rng(1)
    o = rng.uniform(-1.5, 1.5, (1000, 3)).astype(np.float32)
    d = uniform_directions(rng, 1000).astype(np.float32)
    d[:50, rng.integers(0, 3, 50)] = 0.0  # some zero components
    a = ray_box(o, d)
    b = ray_box(torch.from_numpy(o), torch.from_numpy(d))
    for x, y in zip(a, b):
        assert np.array_equal(np.asarray(x, np.float32), y.numpy())


def test_pinhole_rays_look_at_the_target_and_span_the_field_of_view():
    o, d = pinhole_rays((0.0, 0.0, 2.0), np.zeros(3), (0.0, 1.0, 0.0), 60.0, 4, 3)
    assert o.shape == d.shape == (12, 3) and np.allclose(o, [0, 0, 2])
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0) and (d[:, 2] < 0).all()
    grid = d.reshape(3, 4, 3)
    assert grid[0, 0, 1] > 0 > grid[2, 0, 1] and grid[0, 0, 0] < 0 < grid[0, 3, 0]  # row 0 on top, column 0 left
    # the image plane at distance 1: row 0's centre at y = (1 - 1/height) tan(fov/2), column 0's at
    # x = -(1 - 1/width) tan(fov/2) width/height
    plane = grid / -grid[..., 2:]
    assert plane[0, 0, 1] == pytest.approx((1 - 1 / 3) * math.tan(math.radians(30)), rel=1e-9)
    assert plane[0, 0, 0] == pytest.approx(-(1 - 1 / 4) * math.tan(math.radians(30)) * 4 / 3, rel=1e-9)


def test_fourier_features_layout():
    pe = FourierFeatures(2, math.pi)
    v = torch.tensor([[0.25, -0.5]])
    out = pe(v)
    assert out.shape == (1, pe.out_dim(2)) == (1, 10)
    a = torch.tensor([0.25 * math.pi, 0.5 * math.pi, -0.5 * math.pi, -1.0 * math.pi])  # channel-major
    assert torch.allclose(out, torch.cat([v[0], torch.sin(a), torch.cos(a)])[None], atol=1e-6)
    assert torch.equal(FourierFeatures(0, 1.0)(v), v)


def test_the_configs_field_box_is_box_half():
    from omegaconf import OmegaConf

    from ddfbench.core.plugins import CONF_DIR

    assert OmegaConf.load(f"{CONF_DIR}/config.yaml").domain == BOX_HALF
