"""The multiresolution hash grid shared by the line-grid DDF and the hash-grid neural SDF: a lookup at a node reads
that node's table row on a dense level and on a hashed level (indices computed here from Instant-NGP's hash), a
point between nodes blends them trilinearly, and a neural SDF with the grid saves and loads to the same field."""

import torch

from ddfbench.models import load_family
from ddfbench.models._feature_grid import FeatureGrid

HALF = 0.6


def node_point(res, node):
    """The position of integer node (x, y, z) of a level with res cells a side over [-HALF, HALF]^3."""
    return torch.tensor([[-HALF + 2 * HALF * c / res for c in node]], dtype=torch.float64)


def grid():
    torch.manual_seed(0)
    g = FeatureGrid(levels=2, features=3, base=4, finest=32, log2_size=8, half=HALF).double()
    with torch.no_grad():
        g.table.normal_()
    return g


def test_a_node_of_a_dense_level_reads_its_row():
    g = grid()
    assert g.n_dense == 1  # 5^3 = 125 nodes fit 2^8 entries; 33^3 do not
    x, y, z = 1, 3, 2
    row = x + 5 * y + 25 * z  # dense index x + (res+1) y + (res+1)^2 z on level 0
    assert torch.allclose(g.lookup(node_point(4, (x, y, z)))[0, 0], g.table[row])


def test_a_node_of_a_hashed_level_reads_its_hashed_row():
    g = grid()
    x, y, z = 17, 5, 30
    row = 256 + ((x * 1) ^ (y * 2654435761) ^ (z * 805459861)) % 256  # level 1 starts after level 0's 2^8 rows
    assert torch.allclose(g.lookup(node_point(32, (x, y, z)))[0, 1], g.table[row])


def test_a_point_between_two_nodes_blends_them_linearly():
    g = grid()
    a, b = node_point(4, (1, 1, 1)), node_point(4, (2, 1, 1))
    mid = g.lookup(0.25 * a + 0.75 * b)[0, 0]
    assert torch.allclose(mid, 0.25 * g.lookup(a)[0, 0] + 0.75 * g.lookup(b)[0, 0])


def test_a_hash_grid_neural_sdf_round_trips_through_its_artifact(tmp_path):
    family = load_family("neural_sdf")
    cfg = {"n_harmonics": 0, "width": 16, "depth": 2, "grid_levels": 3, "grid_base": 4, "grid_finest": 16,
           "grid_log2_size": 10}
    rep = family(cfg)
    with torch.no_grad():
        rep.net.grid.table.normal_(0, 0.1)
    points = torch.rand(64, 3) - 0.5
    path = rep.save(str(tmp_path / "model"))
    again = family.load(path)
    assert torch.equal(again.net(points), rep.net(points))
    assert again.n_params() == rep.n_params() == 3 * 1024 * 2 + (1 + 3 * 2 + 3) * 16 + 17 * 16 + 17
