"""The DDF's line-grid encoding: trilinear lookups, the hash, line invariance, training and the artifact."""

import numpy as np
import pytest
import torch

from ddfbench.core.errors import InputError
from ddfbench.models.ddf import DDF
from ddfbench.models.ddf.line_grid import LineGrid
from ddfbench.models.ddf.network import DDFNet, checked_config

HALF = 0.6


def dense_grid(res: int) -> LineGrid:
    """One dense level: (res+1)^3 nodes fit in the 2^15 table."""
    return LineGrid(points=4, levels=1, features=1, base=res, finest=res, log2_size=15, half=HALF)


def test_a_dense_level_interpolates_a_linear_function_of_the_nodes_exactly():
    res = 8
    grid = dense_grid(res)
    assert grid.n_dense == 1
    i, j, k = np.meshgrid(*[np.arange(res + 1)] * 3, indexing="ij")
    with torch.no_grad():
        grid.table.zero_()
        flat = (i + (res + 1) * j + (res + 1) ** 2 * k).ravel()
        grid.table[flat, 0] = torch.as_tensor((i + 2.0 * j - 3.0 * k).ravel(), dtype=torch.float32)
    q = torch.rand(500, 3, generator=torch.Generator().manual_seed(0)) * 2 * HALF - HALF
    q[:20, 0] = HALF   # on the +x face: the last cell, weight 1 on its far node
    q[20:40] = -HALF   # the -x-y-z corner
    c = (q + HALF) / (2 * HALF) * res  # continuous node coordinates
    expect = c[:, 0] + 2 * c[:, 1] - 3 * c[:, 2]
    got = grid.lookup(q)[:, 0, 0]
    assert torch.allclose(got, expect, atol=1e-4)


def test_hashed_levels_read_the_hashed_entry_at_a_node_and_stay_in_the_table():
    grid = LineGrid(points=4, levels=3, features=2, base=4, finest=64, log2_size=10, half=HALF)
    assert grid.res.tolist() == [4, 16, 64] and grid.n_dense == 1  # 5^3 = 125 <= 1024 < 17^3
    node = torch.tensor([[3, 11, 7]])
    q = node / 16.0 * 2 * HALF - HALF  # exactly on a node of level 1
    h = (3 * 1) ^ (11 * 2654435761) ^ (7 * 805459861)
    entry = 1 * 1024 + h % 1024
    got = grid.lookup(q.float())[0, 1]
    assert torch.allclose(got, grid.table[entry], atol=1e-6)
    far = torch.tensor([[5.0, -5.0, 0.3]])  # beyond the box: clamped onto its faces, still a table entry
    assert torch.isfinite(grid.lookup(far)).all()
    nan = grid.lookup(torch.tensor([[float("nan"), 0.0, 0.0]]))  # NaN in, NaN out: no out-of-range index
    assert torch.isnan(nan).all()


def test_a_table_too_small_for_any_dense_level_hashes_every_level():
    grid = LineGrid(points=2, levels=2, features=2, base=32, finest=64, log2_size=10, half=HALF)
    assert grid.n_dense == 0
    q = torch.rand(100, 3) - 0.5
    assert torch.isfinite(grid.lookup(q)).all()


def test_the_points_span_the_lines_chord_through_the_box():
    """K = 2 reads at 1/4 and 3/4 of the chord; the chord is found here by marching the line."""
    grid = LineGrid(points=2, levels=1, features=1, base=4, finest=4, log2_size=10, half=HALF)
    read = []
    grid.lookup = lambda q: read.append(q) or q.new_zeros(len(q), 1, 1)  # record the points it reads
    foot = torch.tensor([[0.0, 0.0, 0.0], [0.3, -0.2, 0.0], [0.1, 0.25, 0.0]])
    d = torch.nn.functional.normalize(torch.tensor([[0.0, 0.0, 1.0], [0.4, 0.6, 0.0], [0.0, 0.0, -1.0]]), dim=1)
    foot[1] -= (foot[1] * d[1]).sum() * d[1]
    out = grid(foot, d)
    u = torch.linspace(-2, 2, 400001)
    for i in range(3):
        inside = ((foot[i] + u[:, None] * d[i]).abs() <= HALF + 1e-9).all(1)
        lo, hi = u[inside].min(), u[inside].max()
        assert torch.allclose(out[i, -2:], torch.stack([lo, hi]), atol=2e-5)
        expect = torch.stack([foot[i] + (lo + f * (hi - lo)) * d[i] for f in (0.25, 0.75)])
        assert torch.allclose(read[0].view(3, 2, 3)[i], expect, atol=2e-5)


def test_features_are_the_same_anywhere_along_a_line_and_their_gradients_finite():
    grid = LineGrid(points=6, levels=4, features=2, base=4, finest=32, log2_size=12, half=HALF)
    with torch.no_grad():
        grid.table.normal_()
    g = torch.Generator().manual_seed(1)
    x = torch.rand(64, 3, generator=g) - 0.5
    d = torch.nn.functional.normalize(torch.randn(64, 3, generator=g), dim=1)
    d[:8] = torch.tensor([0.0, 0.0, 1.0])        # parallel to an axis: ray_box's flat slabs
    x[8:12] = torch.tensor([2.0, 2.0, 0.0])      # lines that miss the box
    foot = lambda p: p - (p * d).sum(-1, keepdim=True) * d  # noqa: E731
    a = grid(foot(x), d)
    b = grid(foot(x + 0.37 * d), d)
    assert a.shape == (64, grid.out_dim()) and torch.allclose(a, b, atol=1e-4)  # float32 foot points
    x.requires_grad_(True)
    (grad,) = torch.autograd.grad(grid(foot(x), d).sum(), x)
    assert torch.isfinite(grad).all()


def test_the_net_with_a_line_grid_trains_and_its_table_learns():
    torch.manual_seed(0)
    cfg = checked_config({"width": 32, "depth": 2, "line_grid_points": 4, "line_grid_levels": 3,
                          "line_grid_finest": 32, "line_grid_log2_size": 12})
    net = DDFNet(cfg)
    assert net.grid is not None and net.body[0].in_features == net.pos_pe.out_dim(4) + net.dir_pe.out_dim(3) + 4 * 3 * 2 + 2
    g = torch.Generator().manual_seed(2)
    x = torch.rand(512, 3, generator=g) - 0.5
    d = torch.nn.functional.normalize(torch.randn(512, 3, generator=g), dim=1)
    target = 0.3 + 0.2 * torch.sin(7 * x[:, 0])
    start = net.grid.table.detach().clone()
    opt = torch.optim.Adam(net.parameters(), 1e-2)
    losses = []
    for _ in range(60):
        dist, _ = net(x, d)
        loss = (dist - target).abs().mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.5 * losses[0]
    assert (net.grid.table.detach() - start).abs().max() > 1e-3


def test_a_ddf_with_a_line_grid_round_trips_through_its_artifact(tmp_path):
    rep = DDF({"width": 32, "depth": 2, "line_grid_points": 4, "line_grid_levels": 2, "line_grid_log2_size": 10})
    with torch.no_grad():
        rep.net.grid.table.normal_()
    back = DDF.load(rep.save(str(tmp_path / "model")))
    g = np.random.default_rng(3)
    o = (g.normal(size=(200, 3)) * 1.5).astype(np.float32)
    d = (-o / np.linalg.norm(o, axis=1, keepdims=True)).astype(np.float32)
    a, b = rep.intersect(o, d, normals=False), back.intersect(o, d, normals=False)
    assert np.array_equal(a.t, b.t) and np.array_equal(a.hit, b.hit)
    table = sum(p.numel() for name, p in rep.net.named_parameters() if name.startswith("grid."))
    assert table == 2 * 2**10 * 2  # the table is a parameter: stored in the artifact, counted in n_params


@pytest.mark.parametrize("override", [{"line_grid_points": -1}, {"line_grid_levels": 0}, {"line_grid_log2_size": 30},
                                      {"line_grid_base": 64, "line_grid_finest": 32}])
def test_bad_line_grid_settings_are_one_line_errors(override):
    with pytest.raises(InputError, match="model.line_grid_"):
        DDF(override)
