"""Shape suite v1: the shapes the cross-shape experiments run on, each with its split, provenance and license.

The split is fixed and disjoint: `tuning` shapes are the only ones a tuning study may see, `evaluation`
shapes the only ones the suite's reports rank on. The split spreads each difficulty axis (measured by
ddfbench.truth.difficulty) over both sides: tuning holds an organic scan (cow), a smooth genus-1 solid
(torus), a sharp-edged genus-5 part (gear) and an open surface (open_box). No tuning shape is a version of an
evaluation shape (bunny10k, a coarser bunny, is in neither split).

    python -m ddfbench.report results/shape_suite --out reports/shape_suite     shapes and tags, families, axes
"""

from __future__ import annotations

from dataclasses import dataclass

PYMESHLAB = "pymeshlab test data (the package: GPL-3.0; the mesh's own license is not stated)"
BUILT = "built by ddfbench (MIT)"


@dataclass(frozen=True)
class SuiteShape:
    """One shape of the suite: its catalog name, split ('tuning' | 'evaluation'), where it comes from, license."""

    name: str
    split: str
    kind: str
    provenance: str
    license: str


SUITE_V1 = (
    SuiteShape("cow", "tuning", "scan", "pymeshlab sample cow.obj", PYMESHLAB),
    SuiteShape("torus", "tuning", "primitive", "trimesh.creation.torus (R 0.35, r 0.15)", BUILT),
    SuiteShape("gear", "tuning", "cad", "manifold3d CSG (ddfbench/truth/cad.py)", BUILT),
    SuiteShape("open_box", "tuning", "cad, open", "the unit box without its top face (ddfbench/truth/catalog.py)", BUILT),
    SuiteShape("bunny", "evaluation", "scan",
               "pymeshlab sample bunny.obj (the Stanford bunny, Stanford 3D Scanning Repository)", PYMESHLAB),
    SuiteShape("airplane", "evaluation", "model", "pymeshlab sample airplane.obj", PYMESHLAB),
    SuiteShape("bone", "evaluation", "scan", "pymeshlab sample bone.ply", PYMESHLAB),
    SuiteShape("range_scan", "evaluation", "scan, open", "pymeshlab sample rangemaps/face000.ply", PYMESHLAB),
    SuiteShape("sphere", "evaluation", "primitive", "trimesh.creation.icosphere (r 0.5, 4 subdivisions)", BUILT),
    SuiteShape("capsule", "evaluation", "primitive", "trimesh.creation.capsule (h 0.5, r 0.25)", BUILT),
    SuiteShape("box", "evaluation", "primitive", "trimesh.creation.box (1 x 0.6 x 0.4)", BUILT),
    SuiteShape("bracket", "evaluation", "cad", "manifold3d CSG (ddfbench/truth/cad.py)", BUILT),
    SuiteShape("lattice", "evaluation", "cad", "manifold3d CSG (ddfbench/truth/cad.py)", BUILT),
    SuiteShape("cup", "evaluation", "cad", "manifold3d CSG (ddfbench/truth/cad.py)", BUILT),
    SuiteShape("perforated_plate", "evaluation", "cad", "manifold3d CSG (ddfbench/truth/cad.py)", BUILT),
    SuiteShape("chain", "evaluation", "cad", "manifold3d CSG (ddfbench/truth/cad.py)", BUILT),
)


def split(name: str, suite: tuple[SuiteShape, ...] = SUITE_V1) -> list[str]:
    """The catalog names of one split ('tuning' | 'evaluation'), in suite order."""
    return [s.name for s in suite if s.split == name]
