"""The report's gallery: the extracted mesh seen from the run's camera, and no figure without renders."""

import numpy as np
import trimesh

from ddfbench.report.gallery import _BACKGROUND, row_label, shaded_mesh_view, write_gallery

SCENE = {"outputs": ["depth"], "width": 32, "height": 24, "cameras": {"n": 1, "radius": 2.0, "elevation_deg": 0.0, "azimuth_deg": 0.0,
                                                 "fov_deg": 40.0}}


def test_mesh_view_lights_the_mesh_and_leaves_the_rest_background(tmp_path, capsys):
    path = str(tmp_path / "box.ply")
    trimesh.creation.box(extents=(0.5, 0.5, 0.5)).export(path)
    image = shaded_mesh_view(path, SCENE)
    assert image.shape == (24, 32, 3)
    background = np.all(np.isclose(image, _BACKGROUND), axis=-1)
    assert not background[12, 16] and background[0, 0] and background[23, 31]  # box in the middle only
    assert 0.1 < (~background).mean() < 0.6
    assert np.all(shaded_mesh_view(str(tmp_path / "missing.ply"), SCENE) == _BACKGROUND)
    assert capsys.readouterr().err == f"ddfbench.report: {tmp_path / 'missing.ply'}: missing; its gallery panel is left blank\n"


def test_no_renders_no_gallery(tmp_path):
    records = [{"status": "ok", "model": "mesh", "shape": {"name": "cube"}, "artifacts": {}, "_dir": str(tmp_path)}]
    assert write_gallery(records, str(tmp_path)) is None
    assert not (tmp_path / "gallery.png").exists()


def test_a_row_is_not_converged_only_when_every_run_it_shows_gave_no_result():
    ok = {"status": "ok", "metrics": {"chamfer_l2": 1e-5, "fscore": {"0.02": 1.0}}}
    empty = {"status": "ok", "metrics": {"chamfer_l2": 3.0, "empty_reconstruction": True, "fscore": {"0.02": 0.0}}}
    off = {"status": "ok", "metrics": {"chamfer_l2": 0.5, "fscore": {"0.02": 0.0}}}  # a surface, nowhere near
    cells = {("mesh", "bunny"): ok, ("ddf_paper", "bunny"): empty, ("ddf_paper", "cow"): ok,
             ("gan_sdf", "bunny"): empty, ("gan_sdf", "cow"): off}
    assert row_label("mesh", cells) == "mesh"
    assert row_label("ddf_paper", cells) == "ddf_paper\n(no result in 1 of 2)"
    assert row_label("gan_sdf", cells) == "gan_sdf\n(not converged)"
