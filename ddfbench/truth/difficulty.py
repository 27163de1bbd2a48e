"""Difficulty tags measured from a normalized mesh (longest side 1): what makes a shape hard to represent.

Every tag is computed from the triangles alone, with a fixed seed, so the same mesh always gets the same tags:

    thinnest      1st percentile of the local wall thickness (units of the longest side): from N surface
                  samples, the distance along the inward normal to the next surface. None for an open mesh
                  (no inside), the smallest feature a field has to resolve otherwise.
    genus         total genus: (2 C - chi - b) / 2 with chi = V - E + F of the welded mesh, C its components and
                  b its boundary loops (a handle, a hole through the part, counts 1).
    sharp_edges   length of the edges whose dihedral angle exceeds 30 degrees, over sqrt(surface area): crease
                  length per unit size, independent of how flat regions are triangulated (0: smooth; a 1 x 0.6 x 0.4
                  box: 5.1).
    detail        the 90th percentile over the surface of |mean curvature| (1 / longest side) in balls of radius
                  0.01: how curved the finest tenth of the surface is (a sphere of radius 0.5: about 2-4, the
                  bunny 16, a crease about 50), so small features and creases both count.
    open_boundary share of the edge length on the boundary (0: closed).
    components    connected pieces of the welded mesh.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import trimesh

from ddfbench.truth.oracle import Oracle

SHARP_DEGREES = 30.0
DETAIL_RADIUS = 0.01
DETAIL_QUANTILE = 0.9
THICKNESS_QUANTILE = 0.01


@dataclass(frozen=True)
class Difficulty:
    """The tags of one shape (see the module docstring for each definition and unit)."""

    faces: int
    thinnest: float | None
    genus: int
    sharp_edges: float
    detail: float
    open_boundary: float
    components: int

    def as_dict(self) -> dict[str, float | int | None]:
        return asdict(self)


def welded(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """The mesh with coincident vertices merged (topology by position, not by the file's indexing)."""
    out = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), process=False)
    out.merge_vertices(merge_tex=True, merge_norm=True)
    return out


def boundary_edges(mesh: trimesh.Trimesh) -> np.ndarray:
    """(B, 2) vertex pairs of the edges used by exactly one face."""
    edges = np.sort(mesh.edges, axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    return unique[counts == 1]


def genus(mesh: trimesh.Trimesh) -> int:
    """Total genus of a welded mesh from its Euler characteristic, components and boundary loops."""
    boundary = boundary_edges(mesh)
    loops = 0
    if len(boundary):
        graph = trimesh.graph.nx.Graph()
        graph.add_edges_from(map(tuple, boundary))
        loops = trimesh.graph.nx.number_connected_components(graph)
    chi = len(mesh.vertices) - len(mesh.edges_unique) + len(mesh.faces)
    return int(round((2 * components(mesh) - chi - loops) / 2))


def components(mesh: trimesh.Trimesh) -> int:
    """Connected pieces of a welded mesh (faces joined through shared edges)."""
    return len(trimesh.graph.connected_components(mesh.face_adjacency, nodes=np.arange(len(mesh.faces))))


def crease_length(mesh: trimesh.Trimesh, degrees: float = SHARP_DEGREES) -> float:
    """Length of the edges whose faces meet at more than `degrees` (between normals), over sqrt(area)."""
    pairs = mesh.face_adjacency_edges
    if len(pairs) == 0:
        return 0.0
    length = np.linalg.norm(mesh.vertices[pairs[:, 0]] - mesh.vertices[pairs[:, 1]], axis=1)
    sharp = mesh.face_adjacency_angles > np.radians(degrees)
    return float(length[sharp].sum() / np.sqrt(mesh.area))


def thinnest(mesh: trimesh.Trimesh, n: int = 20000, seed: int = 0) -> float | None:
    """THICKNESS_QUANTILE of the inward ray distance from n area-uniform surface samples; None if open."""
    if not mesh.is_watertight:
        return None
    points, faces = trimesh.sample.sample_surface(mesh, n, seed=seed)
    inward = -mesh.face_normals[faces] * (1.0 if mesh.volume > 0 else -1.0)
    start = points + 1e-6 * inward
    distance = Oracle(mesh).hit_distance(start, inward)
    distance = distance[np.isfinite(distance)]
    return float(np.quantile(distance, THICKNESS_QUANTILE)) if len(distance) else None


def detail(mesh: trimesh.Trimesh, n: int = 2000, seed: int = 0, radius: float = DETAIL_RADIUS) -> float:
    """DETAIL_QUANTILE of |mean curvature| (1 / longest side) at n surface samples, each the curvature measure
    of a ball of `radius` over the ball's disc area (a sphere of radius R reads about 1 / R; a right-angle
    crease saturates near 1 / (2 radius), 50 at radius 0.01)."""
    points, _ = trimesh.sample.sample_surface(mesh, n, seed=seed)
    measure = trimesh.curvature.discrete_mean_curvature_measure(mesh, points, radius)
    return float(np.quantile(np.abs(measure) / (np.pi * radius**2), DETAIL_QUANTILE))


def difficulty(mesh: trimesh.Trimesh) -> Difficulty:
    """Every tag of a normalized mesh (vertices in [-0.5, 0.5]^3)."""
    weld = welded(mesh)
    boundary = boundary_edges(weld)
    edge_length = np.linalg.norm(np.diff(weld.vertices[weld.edges_unique], axis=1)[:, 0], axis=1).sum()
    open_length = np.linalg.norm(weld.vertices[boundary[:, 0]] - weld.vertices[boundary[:, 1]], axis=1).sum()
    return Difficulty(faces=int(len(mesh.faces)), thinnest=thinnest(weld), genus=genus(weld),
                      sharp_edges=crease_length(weld), detail=detail(weld),
                      open_boundary=float(open_length / edge_length), components=components(weld))
