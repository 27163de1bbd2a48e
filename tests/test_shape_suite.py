"""Shape suite v1: the CAD shapes are the solids they are built to be, the difficulty tags measure what they
say on shapes whose answer is known by hand, and the split is disjoint and matches the experiment."""

import math
import os

import pytest
import trimesh
import yaml

from ddfbench.core.plugins import CONF_DIR
from ddfbench.truth import cad, catalog, difficulty, suite
from ddfbench.truth.shapes import load_shape


@pytest.mark.parametrize("name,genus,components", [
    ("bracket", 6, 1),            # four holes in the base, two in the upright
    ("gear", 5, 1),               # the bore and four lightening holes
    ("cup", 0, 1),
    ("perforated_plate", 25, 1),  # a 5 x 5 array of through-holes
    ("chain", 2, 2),              # two linked rings
])
def test_cad_shapes_are_closed_solids_of_their_designed_topology(name, genus, components):
    mesh = difficulty.welded(cad.CAD_BUILDERS[name]())
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    assert difficulty.genus(mesh) == genus
    assert difficulty.components(mesh) == components


def test_lattice_struts_meet_without_pinched_vertices():
    mesh = difficulty.welded(cad.lattice(cells=2, strut=0.1))
    # 2 x 2 x 2 cells: the frame's graph has 27 nodes and 54 struts, genus 54 - 27 + 1 = 28
    assert mesh.is_watertight and difficulty.genus(mesh) == 28


def test_bad_cad_parameters_name_the_shape_and_value():
    with pytest.raises(Exception, match=r"gear: teeth 3"):
        cad.gear(teeth=3)
    with pytest.raises(Exception, match=r"cup: .*wall 0.5"):
        cad.cup(wall=0.5)


def test_thinnest_is_the_wall_of_a_thin_plate_and_none_for_an_open_mesh():
    plate = load_shape({"name": "hard/thin_plate", "params": {"thickness": 0.02}}).mesh
    assert difficulty.thinnest(plate) == pytest.approx(0.02, rel=1e-3)
    assert difficulty.thinnest(catalog.open_box()) is None


def test_genus_and_open_boundary_on_primitives():
    assert difficulty.genus(difficulty.welded(trimesh.creation.torus(0.35, 0.15))) == 1
    assert difficulty.genus(difficulty.welded(trimesh.creation.icosphere(3))) == 0
    box = difficulty.difficulty(catalog.open_box())
    # the missing top leaves 4 boundary edges of 1 among 12 edges of 1 and 5 face diagonals of sqrt(2)
    assert box.open_boundary == pytest.approx(4 / (12 + 5 * math.sqrt(2)))
    assert box.genus == 0 and box.components == 1


def test_crease_length_counts_the_box_edges_not_its_diagonals():
    box = trimesh.creation.box(extents=(1.0, 0.6, 0.4))
    crease = 4 * (1.0 + 0.6 + 0.4)
    area = 2 * (0.6 + 0.4 + 0.24)
    assert difficulty.crease_length(difficulty.welded(box)) == pytest.approx(crease / math.sqrt(area))
    assert difficulty.crease_length(difficulty.welded(trimesh.creation.icosphere(4))) == 0.0


def test_detail_reads_the_curvature_of_a_sphere_and_grows_on_smaller_spheres():
    big = difficulty.detail(trimesh.creation.icosphere(5, radius=0.5))
    small = difficulty.detail(trimesh.creation.icosphere(5, radius=0.1))
    assert 1.0 < big < 4.0            # mean curvature of a radius-0.5 sphere: 2
    assert small == pytest.approx(5 * big, rel=0.3)


def test_the_split_is_disjoint_covers_the_minimums_and_every_shape_is_in_the_catalog():
    tuning, evaluation = suite.split("tuning"), suite.split("evaluation")
    assert len(tuning) >= 4 and len(evaluation) >= 12 and not set(tuning) & set(evaluation)
    assert len(tuning) + len(evaluation) == len(suite.SUITE_V1)
    known = set(catalog.PYMESHLAB_SAMPLES) | set(catalog.BUILDERS)
    assert {s.name for s in suite.SUITE_V1} <= known
    assert all(s.provenance and s.license for s in suite.SUITE_V1)


@pytest.mark.parametrize("experiment", ["shape_suite", "render_shapes"])
def test_the_experiment_sweeps_exactly_the_evaluation_split(experiment):
    with open(f"{CONF_DIR}/experiment/{experiment}.yaml") as f:
        swept = yaml.safe_load(f)["hydra"]["sweeper"]["params"]["shape"].split(",")
    assert swept == suite.split("evaluation")
    assert all(os.path.exists(f"{CONF_DIR}/shape/{name}.yaml") for name in swept)
