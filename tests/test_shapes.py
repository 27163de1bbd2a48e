"""Loading, validation and normalization; every bad input gets a one-line error naming the file."""

import os

import numpy as np
import pytest
import trimesh

from ddfbench.core.errors import InputError
from ddfbench.truth.shapes import PYMESHLAB_SAMPLES, catalog, load_shape


def load_file(path):
    return load_shape({"name": "file", "path": str(path)})


def expect_error(path, fragment):
    with pytest.raises(InputError) as info:
        load_file(path)
    msg = str(info.value)
    assert "\n" not in msg
    assert str(path) in msg
    assert fragment in msg
    return msg


def test_missing_path(tmp_path):
    expect_error(tmp_path / "nope.obj", "does not exist")


def test_empty_file(tmp_path):
    p = tmp_path / "empty.obj"
    p.write_bytes(b"")
    expect_error(p, "empty")


def test_unreadable_bytes(tmp_path):
    p = tmp_path / "junk.ply"
    p.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 99999\n" + bytes(range(256)) * 3)
    expect_error(p, "could not be parsed")


@pytest.mark.parametrize("name,text,fragment", [
    ("mesh.xyzw", "1 2 3\n", "unsupported format"),
    ("nan.obj", "v 0 0 0\nv 1 0 0\nv 0 nan 0\nv 0 0 inf\nf 1 2 3\nf 1 2 4\n", "NaN or inf"),
    ("flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "zero area"),
])
def test_bad_text_files(tmp_path, name, text, fragment):
    p = tmp_path / name
    p.write_text(text)
    expect_error(p, fragment)


def test_point_cloud_has_no_faces(tmp_path):
    p = tmp_path / "cloud.ply"
    trimesh.PointCloud(np.random.default_rng(0).normal(size=(50, 3))).export(p)
    expect_error(p, "no faces")


def _write_obj(path, vertices, faces):
    with open(path, "w") as fh:
        fh.writelines(f"v {x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in vertices)
        fh.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in faces)


def test_degenerate_and_duplicate_faces_are_removed_with_warnings(tmp_path):
    box = trimesh.creation.box()
    faces = np.vstack([box.faces, box.faces[:2], [[0, 0, 1]]])
    verts = np.vstack([box.vertices, [[9, 9, 9]]])  # one unreferenced vertex
    p = tmp_path / "dirty.ply"  # PLY keeps unreferenced vertices (the OBJ reader drops them)
    trimesh.Trimesh(verts, faces, process=False).export(p)
    shape = load_file(p)
    assert len(shape.mesh.faces) == 12
    text = " ".join(shape.warnings)
    assert "zero-area" in text and "duplicate" in text and "unreferenced" in text
    assert shape.watertight


def test_an_stl_file_reads_as_the_same_closed_mesh_as_its_obj(tmp_path):
    """STL stores three corners per triangle: read unmerged, a closed torus was a soup (flagged open, its LODs
    decimated apart into a CD-L2 ~200x the OBJ's)."""
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3)
    torus.export(tmp_path / "t.stl")
    torus.export(tmp_path / "t.obj")
    stl, obj = load_file(tmp_path / "t.stl"), load_file(tmp_path / "t.obj")
    assert stl.watertight and obj.watertight
    assert (len(stl.mesh.vertices), len(stl.mesh.faces)) == (len(obj.mesh.vertices), len(obj.mesh.faces))
    assert np.isclose(stl.mesh.area, obj.mesh.area) and np.isclose(stl.mesh.volume, obj.mesh.volume)


def test_an_stl_joins_only_corners_at_exactly_one_position(tmp_path):
    """A part 1e-9 across (trimesh's merge rounds to 1e-8 and would fold it to a point): its corners stay apart."""
    tetra = trimesh.creation.icosphere(0, radius=1.0)
    tiny = trimesh.Trimesh(tetra.vertices * 1e-9, tetra.faces, process=False)
    tiny.export(tmp_path / "tiny.stl")
    shape = load_file(tmp_path / "tiny.stl")
    assert shape.watertight and len(shape.mesh.vertices) == 12 and len(shape.mesh.faces) == 20


def test_an_obj_cut_along_a_seam_reads_closed_and_keeps_its_vertex_order(tmp_path):
    """OBJ (like PLY and glTF) repeats a vertex at a UV seam: the torus with the vertices of one face stored
    again read as open (cut along the seam), its LODs decimated apart (catalog: `cow` repeats 1, `bunny10k`
    1,400). Joined, it is the closed torus; the vertices keep their file order, so a mesh without repeats reads
    exactly as its file stores it."""
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3)
    v, f = np.asarray(torus.vertices), np.asarray(torus.faces)
    k = len(v) // 2
    face = int(np.flatnonzero(f.max(axis=1) < k)[0])  # a face whose corners come before the seam's copies
    v_cut = np.vstack([v[:k], v[f[face]], v[k:]])  # its corners again mid-file, as a UV seam stores them
    f_cut = np.where(f < k, f, f + 3)
    f_cut[face] = [k, k + 1, k + 2]
    _write_obj(tmp_path / "seam.obj", v_cut, f_cut)
    _write_obj(tmp_path / "plain.obj", v, torus.faces)
    assert not trimesh.Trimesh(v_cut, f_cut, process=False).is_watertight
    cut, plain = load_file(tmp_path / "seam.obj"), load_file(tmp_path / "plain.obj")
    assert cut.watertight and len(cut.mesh.vertices) == len(v)
    assert np.array_equal(cut.mesh.vertices, plain.mesh.vertices) and np.array_equal(cut.mesh.faces, plain.mesh.faces)
    assert np.array_equal(plain.mesh.faces, torus.faces)  # the file's own vertex order, not np.unique's sorted one


@pytest.mark.parametrize("offset", [1e3, 1e5, 1e7])
def test_far_from_origin_normalizes_to_the_same_mesh(tmp_path, offset):
    sphere = trimesh.creation.icosphere(2, 0.7)
    p = tmp_path / "far.obj"
    _write_obj(p, sphere.vertices + offset, sphere.faces)
    shape = load_file(p)
    ref = load_shape({"name": "sphere", "params": {"radius": 0.7, "subdivisions": 2}})
    assert np.abs(shape.mesh.vertices - ref.mesh.vertices).max() < 1e-6 * max(1.0, offset / 1e3)
    assert np.allclose(shape.transform["center"], offset, rtol=1e-9)


def test_normalization_puts_longest_side_to_one():
    shape = load_shape({"name": "box"})
    lo, hi = shape.mesh.bounds
    assert np.isclose((hi - lo).max(), 1.0)
    assert np.allclose(0.5 * (lo + hi), 0.0)
    assert shape.transform["scale"] == pytest.approx(1.0)


def test_catalog_resolves_from_installed_pymeshlab():
    for name in ["bunny10k", "bone", "cube"]:
        shape = load_shape({"name": name})
        assert len(shape.mesh.faces) > 0
    assert set(PYMESHLAB_SAMPLES) <= set(catalog())
    assert not load_shape({"name": "bunny10k"}).watertight


def test_unknown_name_lists_catalog():
    with pytest.raises(InputError, match="unknown.*bunny"):
        load_shape({"name": "teapot"})


def test_sample_meshes_from_a_copy_without_pymeshlab(tmp_path, monkeypatch):
    """$DDFBENCH_SAMPLE_MESHES names a copy of the sample folder (a GPU machine gets no pymeshlab wheel): the
    catalog reads from it, and the full-resolution mesh family needs no pymeshlab (only its LODs do)."""
    import shutil
    import sys

    from ddfbench.models.mesh import decimate
    from ddfbench.truth.catalog import SAMPLES_ENV, pymeshlab_samples_dir

    shutil.copy(os.path.join(pymeshlab_samples_dir(), PYMESHLAB_SAMPLES["bone"]), tmp_path / "bone.ply")
    monkeypatch.setenv(SAMPLES_ENV, str(tmp_path))
    monkeypatch.setitem(sys.modules, "pymeshlab", None)  # import pymeshlab -> ImportError
    bone = load_shape({"name": "bone"})
    assert bone.source == str(tmp_path / "bone.ply") and len(bone.mesh.faces) > 1000
    assert decimate(bone.mesh, 0) is bone.mesh
    with pytest.raises(InputError, match=r"model.faces=500: mesh LODs need pymeshlab"):
        decimate(bone.mesh, 500)
    with pytest.raises(InputError, match="cow"):  # not in the copy: the usual one-line error naming the file
        load_shape({"name": "cow"})
    monkeypatch.delenv(SAMPLES_ENV)
    with pytest.raises(InputError, match=SAMPLES_ENV) as err:  # neither pymeshlab nor a copy: say what to set
        load_shape({"name": "bone"})
    assert "\n" not in str(err.value)


def test_a_built_in_samples_record_names_no_path_of_the_machine():
    bunny = load_shape({"name": "bunny"})
    assert bunny.summary()["source"] == "pymeshlab sample bunny.obj" and os.path.isfile(bunny.source)
    assert load_shape({"name": "sphere"}).summary()["source"] == "procedural"
