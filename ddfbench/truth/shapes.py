"""Load, validate and normalize shapes; serve the built-in catalog (ddfbench.truth.catalog) by name.

Every shape is normalized before anything else: bounding-box center to the
origin, longest side to 1 (the unit cube [-0.5, 0.5]^3). Normalization runs in
float64, so meshes far from the origin (1e7) keep their precision.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np
import trimesh

from ddfbench.core.errors import InputError
from ddfbench.truth.catalog import ALIASES, BUILDERS, PYMESHLAB_SAMPLES, pymeshlab_samples_dir

MESH_EXTENSIONS = {"obj", "ply", "stl", "off", "glb", "gltf", "dae", "3mf"}


@dataclass
class Shape:
    """A validated, normalized triangle mesh.

    mesh:      normalized trimesh (float64 vertices in [-0.5, 0.5]^3).
    name:      catalog name or file stem; source: the file read (or "procedural"); provenance: what a record
               names as its source: the user's file as given, a package sample by package and file name (not the
               machine's install path), or "procedural".
    transform: {"center": [3], "scale": s}: normalized = (original - center) * scale.
    warnings:  what validation repaired (degenerate / duplicate faces, unreferenced vertices...).
    """

    mesh: trimesh.Trimesh
    name: str
    source: str
    transform: dict[str, Any]
    watertight: bool
    warnings: list[str] = field(default_factory=list)
    provenance: str | None = None  # None: source

    def summary(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "source": self.provenance or self.source,
            "n_vertices": int(len(self.mesh.vertices)),
            "n_faces": int(len(self.mesh.faces)),
            "watertight": bool(self.watertight),
            "transform": self.transform,
            "warnings": list(self.warnings),
        }


def catalog() -> list[str]:
    """Every built-in shape name (the hard cases under hard/...)."""
    return sorted(PYMESHLAB_SAMPLES) + sorted(SHAPE_BUILDERS) + sorted(ALIASES)


def read_mesh_file(path: str) -> trimesh.Trimesh:
    """Parse a mesh file with trimesh; one-line InputError naming the file on any problem."""
    if not path or path == "???":  # "???": OmegaConf's mark of a value conf/shape/file.yaml leaves to the user
        raise InputError("shape.path is not set: give a mesh file (e.g. shape=file shape.path=/data/chair.obj)")
    if not os.path.exists(path):
        raise InputError(f"shape file {path}: does not exist")
    if os.path.isdir(path):
        raise InputError(f"shape file {path}: is a directory, not a mesh file")
    if os.path.getsize(path) == 0:
        raise InputError(f"shape file {path}: is empty (0 bytes)")
    ext = path.rsplit(".", 1)[-1].lower() if "." in os.path.basename(path) else ""
    if ext not in MESH_EXTENSIONS:
        raise InputError(
            f"shape file {path}: unsupported format '.{ext}' (supported: {', '.join(sorted(MESH_EXTENSIONS))})"
        )
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types on corrupt bytes
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f"shape file {path}: could not be parsed as .{ext} ({msg})") from None
    if isinstance(loaded, trimesh.PointCloud) or not hasattr(loaded, "faces") or len(loaded.faces) == 0:
        raise InputError(f"shape file {path}: has no faces (a point cloud or empty mesh); a triangle mesh is needed")
    return join_corners(loaded)


def join_corners(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The mesh with the vertices that lie at exactly one position made one (the first, in file order; the mesh
    itself where none repeat). STL stores each triangle's own three corners and OBJ, PLY and glTF repeat a vertex
    at a UV or normal seam: unjoined, a closed mesh reads as open (a soup, or cut along its seams) and its LODs
    decimate apart. Exact equality, not trimesh's rounding to 1e-8, so no two distinct corners of a tiny or far-off
    mesh are joined."""
    v = np.asarray(mesh.vertices, np.float64)
    _, first, inverse = np.unique(v, axis=0, return_index=True, return_inverse=True)
    if len(first) == len(v):
        return mesh
    order = np.argsort(first)  # the kept vertices in file order
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return trimesh.Trimesh(v[first[order]], rank[inverse.reshape(-1)][np.asarray(mesh.faces)], process=False)


# a coordinate near the offset 2^k rounds by up to half its ulp, 2^(k - 54): at most 1e-6 of the extent when the
# extent in units of 2^k is at least this (offset 1e10 with extent 1 passes, at 9.5e-7; 1e11 does not)
ROUNDING_LIMIT = 2.0**-54 / 1e-6


def validate(mesh: trimesh.Trimesh, label: str) -> tuple[trimesh.Trimesh, list[str]]:
    """Reject meshes that cannot be benchmarked, repair those that can; return (mesh, warnings).

    Errors: non-finite vertices, no faces, no area, a zero-size box.
    Repairs (each a warning): zero-area faces, duplicate faces, unreferenced vertices.
    """
    v = np.asarray(mesh.vertices, dtype=np.float64)
    f = np.asarray(mesh.faces, dtype=np.int64)
    if len(f) == 0:
        raise InputError(f"{label}: has no faces; a triangle mesh is needed")
    bad = ~np.isfinite(v).all(axis=1)
    if bad.any():
        raise InputError(f"{label}: {int(bad.sum())} vertices have NaN or inf coordinates")
    if f.min() < 0 or f.max() >= len(v):
        raise InputError(f"{label}: faces index vertices that do not exist")
    warnings: list[str] = []
    used_v = v[np.unique(f)]
    offset = float(np.abs(used_v).max())
    if offset == 0.0:
        raise InputError(f"{label}: all vertices coincide (zero-size bounding box)")
    k = math.frexp(offset)[1]
    u = np.ldexp(v, -k)  # the checks run on v / 2^k, max |u| in [0.5, 1): no overflow near float64's range
    extent = float(np.ptp(u[np.unique(f)], axis=0).max())  # in units of 2^k
    if extent <= 0.0:
        raise InputError(f"{label}: all vertices coincide (zero-size bounding box)")
    if extent < ROUNDING_LIMIT:
        raise InputError(f"{label}: extent {math.ldexp(extent, k):g} is too small for its offset {offset:g} "
                         "(float64 precision lost: its coordinates round by more than 1e-6 of the extent)")
    if math.ldexp(extent, k) < 1e-300:  # 1 / extent, the scale to the unit cube, would overflow
        raise InputError(f"{label}: extent {math.ldexp(extent, k):g} is too small to scale to the unit cube")
    tri = u[f] - u[f].mean(axis=(0, 1))
    area2 = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    degenerate = area2 <= 1e-12 * extent**2  # faces below ~1e-6 of the extent on a side
    if degenerate.all():
        raise InputError(f"{label}: every face has zero area")
    if degenerate.any():
        warnings.append(f"removed {int(degenerate.sum())} zero-area faces")
    keep = ~degenerate
    _, first = np.unique(np.sort(f, axis=1), axis=0, return_index=True)
    dup = np.ones(len(f), bool)
    dup[first] = False
    dup &= keep
    if dup.any():
        warnings.append(f"removed {int(dup.sum())} duplicate faces")
        keep &= ~dup
    f = f[keep]
    used = np.zeros(len(v), bool)
    used[f.ravel()] = True
    if not used.all():
        warnings.append(f"removed {int((~used).sum())} unreferenced vertices")
        remap = np.cumsum(used) - 1
        v, f = v[used], remap[f]
    mesh = trimesh.Trimesh(v, f, process=False)
    if not mesh.is_winding_consistent:
        before = mesh.faces.copy()
        trimesh.repair.fix_winding(mesh)
        flipped = int((mesh.faces != before).any(axis=1).sum())
        warnings.append(f"re-wound {flipped} faces that were wound against their neighbours")
        f = np.asarray(mesh.faces)
    return trimesh.Trimesh(v, f, process=False), warnings


def normalize(mesh: trimesh.Trimesh) -> tuple[trimesh.Trimesh, dict[str, Any]]:
    """Center the bounding box at the origin and scale the longest side to 1 (float64, computed on v / 2^k with
    max|v| / 2^k in [0.5, 1): exact scalings, so the result is the same bits as on v itself, and coordinates near
    float64's range do not overflow)."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    k = math.frexp(float(np.abs(v).max()))[1]
    u = np.ldexp(v, -k)
    center_u = 0.5 * (u.min(axis=0) + u.max(axis=0))
    scale_u = 1.0 / float(np.ptp(u, axis=0).max())
    out = trimesh.Trimesh((u - center_u) * scale_u, np.asarray(mesh.faces), process=False)
    return out, {"center": np.ldexp(center_u, k).tolist(), "scale": math.ldexp(scale_u, -k)}


def load_shape(cfg: Mapping[str, Any]) -> Shape:
    """Build a Shape from a `shape` config: {name, path, params}.

    name "file" reads cfg.path; a catalog name reads the pymeshlab sample or builds the procedural shape.
    """
    name = str(cfg.get("name", ""))
    params = dict(cfg.get("params") or {})
    if name == "file":
        path = str(cfg.get("path") or "")
        raw, label, source = read_mesh_file(path), f"shape file {path}", path
        name = os.path.splitext(os.path.basename(path))[0]
    elif name in PYMESHLAB_SAMPLES:
        source = os.path.join(pymeshlab_samples_dir(), PYMESHLAB_SAMPLES[name])
        raw, label = read_mesh_file(source), f"shape {name} ({source})"
    elif ALIASES.get(name, name) in SHAPE_BUILDERS:
        try:
            raw = SHAPE_BUILDERS[ALIASES.get(name, name)](**params)
        except TypeError as exc:
            raise InputError(f"shape {name}: bad params {params} ({exc})") from None
        label, source = f"shape {name}", "procedural"
    elif name.startswith("hard/"):
        raise InputError(f"shape '{name}': unknown hard case (one of {', '.join(HARD_CASES)})")
    else:
        raise InputError(f"shape '{name}': unknown; use shape=file shape.path=... or one of {', '.join(catalog())}")
    mesh, warnings = validate(raw, label)
    mesh, transform = normalize(mesh)
    provenance = f"pymeshlab sample {PYMESHLAB_SAMPLES[name]}" if name in PYMESHLAB_SAMPLES else None
    return Shape(mesh=mesh, name=name, source=source, transform=transform,
                 watertight=bool(mesh.is_watertight), warnings=warnings, provenance=provenance)


def moved(base: str = "cow", offset: float = 1e7, scale: float = 1.0) -> trimesh.Trimesh:
    """Catalog shape `base` (normalized) scaled by `scale`, then translated by offset * (1, -0.7, 0.3), in float64."""
    if not (np.isfinite(offset) and np.isfinite(scale) and scale > 0):
        raise InputError(f"hard/moved: offset {offset!r} must be finite and scale {scale!r} finite and > 0")
    mesh = load_shape({"name": base}).mesh
    v = np.asarray(mesh.vertices, np.float64) * float(scale) + float(offset) * np.array([1.0, -0.7, 0.3])
    return trimesh.Trimesh(v, np.asarray(mesh.faces), process=False)


# every built-in builder by name: the raw catalog's and the one that builds on a loaded shape
SHAPE_BUILDERS: dict[str, Callable[..., trimesh.Trimesh]] = {**BUILDERS, "hard/moved": moved}
HARD_CASES = sorted(n for n in SHAPE_BUILDERS if n.startswith("hard/"))  # the hard-case suite's shapes
