"""The built-in shapes as raw meshes: sample files and mesh builders, before validation and normalization.

The bottom of the shape code: nothing here imports ddfbench.truth.shapes (which validates, normalizes and
serves these by name). A builder `(**params) -> trimesh.Trimesh` returns the raw mesh with any defect
it is meant to carry, so the defect reaches `shapes.validate`. Sizes are in the raw frame; every
builder keeps the longest side at 1 unless it says otherwise, so thicknesses and gaps survive
normalization unchanged. The CAD-like shapes (bracket, gear, lattice, cup, perforated_plate, chain) are
built by CSG in ddfbench.truth.cad. The `hard/...` names are the hard-case suite's meshes built to break things:

    hard/one_triangle     a single triangle
    hard/thin_plate       a 1 x 1 box of `thickness` (0.02), or of `voxels` grid steps of a
                          resolution^3 grid over [-domain, domain]^3 (also served as `thin_plate`)
    hard/plate_pair       two thin plates `gap` apart (default 1e-3)
    open_box              the unit box with its top face removed (non-watertight)
    hard/dirty_sphere     an icosphere with injected zero-area, duplicate and flipped faces
                          and unreferenced vertices (counts are parameters)
    hard/torus_grid       a torus as a (segments x segments/2) quad grid: 1M triangles at segments=1000
    hard/moved            (ddfbench.truth.shapes: it builds on a loaded shape) a catalog shape scaled and moved far away
"""

from __future__ import annotations

import os
from typing import Callable

import numpy as np
import trimesh

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import BOX_HALF
from ddfbench.truth.cad import CAD_BUILDERS

# name -> file below the pymeshlab sample folder
PYMESHLAB_SAMPLES = {
    "bunny": "bunny.obj",
    "bunny10k": "bunny10k_textured.obj",  # non-watertight
    "airplane": "airplane.obj",
    "cow": "cow.obj",
    "bone": "bone.ply",
    "cube": "cube.obj",
    "range_scan": "rangemaps/face000.ply",  # an open range scan
}


SAMPLES_ENV = "DDFBENCH_SAMPLE_MESHES"


def pymeshlab_samples_dir() -> str:
    """Folder of the sample meshes shipped inside the installed pymeshlab package, or the folder that
    $DDFBENCH_SAMPLE_MESHES names (a copy of it, for a machine without pymeshlab)."""
    if os.environ.get(SAMPLES_ENV):
        return os.environ[SAMPLES_ENV]
    try:
        import pymeshlab
    except ImportError as exc:
        raise InputError(f"the sample meshes come with pymeshlab, which is not installed ({exc}); set "
                         f"{SAMPLES_ENV} to a folder holding them (bunny.obj, cow.obj, ...)") from None

    return os.path.join(os.path.dirname(pymeshlab.__file__), "tests", "sample_meshes")


def grid_step(resolution: int, domain: float = BOX_HALF) -> float:
    """Node spacing of a resolution^3 grid over [-domain, domain]^3 (geometry.grid_axis's spacing)."""
    return 2.0 * float(domain) / (int(resolution) - 1)


def open_box() -> trimesh.Trimesh:
    """The unit box without its top (+z) face: open, not watertight."""
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    top = box.face_normals[:, 2] > 0.5
    return trimesh.Trimesh(box.vertices, box.faces[~top], process=False)


def one_triangle() -> trimesh.Trimesh:
    """One right triangle with unit legs in the z = 0 plane."""
    return trimesh.Trimesh([[0.0, 0, 0], [1.0, 0, 0], [0.0, 1, 0]], [[0, 1, 2]], process=False)


def thin_plate(thickness: float | None = None, voxels: float | None = None, resolution: int = 64,
               domain: float = BOX_HALF) -> trimesh.Trimesh:
    """A closed 1 x 1 x thickness box centred at the origin (thickness = voxels * grid_step if given; default 0.02)."""
    if thickness is not None and voxels is not None:
        raise InputError(f"hard/thin_plate: give thickness ({thickness}) or voxels ({voxels}), not both")
    h = float(voxels) * grid_step(resolution, domain) if voxels is not None else float(thickness or 0.02)
    if not 0.0 < h <= 1.0:
        raise InputError(f"hard/thin_plate: thickness {h:g} must be in (0, 1]")
    return trimesh.creation.box(extents=(1.0, 1.0, h))


def plate_pair(gap: float = 1e-3, thickness: float = 0.02) -> trimesh.Trimesh:
    """Two closed 1 x 1 x thickness plates stacked along z with `gap` of empty space between them.

    The lower plate's top face is z = -gap/2, the upper plate's bottom face z = +gap/2.
    """
    if not (gap > 0 and thickness > 0 and 2 * thickness + gap <= 1.0):
        raise InputError(f"hard/plate_pair: gap {gap:g} and thickness {thickness:g} must be > 0 and fit in 1")
    plates = []
    for sign in (-1.0, 1.0):
        box = trimesh.creation.box(extents=(1.0, 1.0, thickness))
        box.apply_translation((0.0, 0.0, sign * (gap + thickness) / 2))
        plates.append(box)
    return trimesh.util.concatenate(plates)


def dirty_sphere(subdivisions: int = 2, zero_area: int = 3, duplicate: int = 4, flipped: int = 5,
                 unreferenced: int = 6, seed: int = 0) -> trimesh.Trimesh:
    """An icosphere (radius 0.5) with defects injected in known numbers.

    zero_area:    faces that repeat a vertex index (i, i, j) or join three collinear vertices.
    duplicate:    copies of existing faces, with the vertex order rotated or reversed.
    flipped:      faces whose winding is reversed in place (a single orientation error each).
    unreferenced: vertices no face uses, placed far outside (at distance 50) so a bounding box
                  that counted them would be visibly wrong.
    """
    rng = np.random.default_rng(seed)
    base = trimesh.creation.icosphere(subdivisions, 0.5)
    v, f = np.array(base.vertices), np.array(base.faces)
    picks = rng.choice(len(f), size=duplicate + flipped, replace=False)
    f[picks[duplicate:]] = f[picks[duplicate:], ::-1]
    dups = [np.roll(f[i], 1) if k % 2 else f[i, ::-1] for k, i in enumerate(picks[:duplicate])]
    bad, extra = [], []
    for k in range(zero_area):
        a, b = f[k, 0], f[k, 1]
        if k % 2:
            extra.append(0.5 * (v[a] + v[b]))  # midpoint: collinear with a and b
            bad.append([a, len(v) + len(extra) - 1, b])
        else:
            bad.append([a, a, b])
    far = rng.normal(size=(unreferenced, 3))
    far = 50.0 * far / np.linalg.norm(far, axis=1, keepdims=True)
    vertices = np.vstack([v, np.reshape(extra, (-1, 3)), far])
    faces = np.vstack([f, np.reshape(dups, (-1, 3)), np.reshape(bad, (-1, 3))]).astype(np.int64)
    return trimesh.Trimesh(vertices, faces, process=False)


def torus_grid(segments: int = 1000, major_radius: float = 0.35, minor_radius: float = 0.15) -> trimesh.Trimesh:
    """A watertight torus around z from a segments x (segments // 2) quad grid: segments^2 triangles.

    Built with numpy in well under a second at 1M triangles. Its exact signed distance is
    |(sqrt(x^2 + y^2) - major_radius, z)| - minor_radius, up to the facets' sag.
    """
    n, m = int(segments), int(segments) // 2
    if n < 6 or not 0 < minor_radius < major_radius:
        raise InputError(f"hard/torus_grid: segments {n} must be >= 6 and 0 < minor {minor_radius} < major {major_radius}")
    u = np.linspace(0, 2 * np.pi, n, endpoint=False)[:, None]
    w = np.linspace(0, 2 * np.pi, m, endpoint=False)[None, :]
    ring = major_radius + minor_radius * np.cos(w)
    v = np.stack([ring * np.cos(u), ring * np.sin(u), np.broadcast_to(minor_radius * np.sin(w), (n, m))], -1)
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    a, b = i * m + j, ((i + 1) % n) * m + j
    c, d = ((i + 1) % n) * m + (j + 1) % m, i * m + (j + 1) % m
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return trimesh.Trimesh(v.reshape(-1, 3), faces, process=False)


# catalog name -> raw mesh builder; each builder is registered under exactly one name
BUILDERS: dict[str, Callable[..., trimesh.Trimesh]] = {
    "sphere": lambda radius=0.5, subdivisions=4: trimesh.creation.icosphere(subdivisions, radius),
    "torus": lambda major_radius=0.35, minor_radius=0.15: trimesh.creation.torus(major_radius, minor_radius),
    "box": lambda extents=(1.0, 0.6, 0.4): trimesh.creation.box(extents=extents),
    "capsule": lambda height=0.5, radius=0.25: trimesh.creation.capsule(height=height, radius=radius),
    "open_box": open_box,
    "hard/one_triangle": one_triangle,
    "hard/thin_plate": thin_plate,
    "hard/plate_pair": plate_pair,
    "hard/dirty_sphere": dirty_sphere,
    "hard/torus_grid": torus_grid,
    **CAD_BUILDERS,  # bracket, gear, lattice, cup, perforated_plate, chain (ddfbench.truth.cad)
}
# short names kept for configs written before the hard-case names (conf/shape/thin_plate.yaml)
ALIASES = {"thin_plate": "hard/thin_plate"}
