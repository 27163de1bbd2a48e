"""Points on a mesh's faces: which faces (per face or area-weighted) and where on them (barycentric)."""

from __future__ import annotations

import numpy as np
import trimesh

FACE_MODES = ("per_face", "total")
BARYCENTRIC_RULES = ("uniform", "paper_eq9")
EDGE_MARGIN = 1e-4  # weights are shrunk toward the centroid by this share: no label ray grazes an edge


def face_plan(mesh: trimesh.Trimesh, s_fc: int, mode: str, rng: np.random.Generator) -> np.ndarray:
    """Face index (N,) int64 of every surface point to draw; zero-area faces never appear.

    per_face: s_fc points on every face of positive area (the paper); total: s_fc x (faces of
    positive area) points, each face drawn with probability proportional to its area.
    """
    area = np.asarray(mesh.area_faces, np.float64)
    if mode == "per_face":
        return np.repeat(np.flatnonzero(area > 0), s_fc)
    cum = np.cumsum(area)
    n = s_fc * int((area > 0).sum())
    faces = np.searchsorted(cum, rng.random(n) * cum[-1], side="right")  # a zero-width interval is never picked
    return np.sort(np.minimum(faces, len(area) - 1))


def barycentric(rng: np.random.Generator, n: int, rule: str) -> tuple[np.ndarray, np.ndarray]:
    """Weights (a, b), each (n,), of edges v1-v0 and v2-v0.

    uniform: a, b ~ U[0,1] folded back into the triangle where a + b > 1 (uniform over the area).
    paper_eq9: the DDF paper's Eq. 9 literally, without the fold: half the points leave the triangle.
    Both are then shrunk toward the centroid by EDGE_MARGIN (a ray through an edge is where two
    ray-cast backends may disagree); the change to the distribution is invisible at 1e-4.
    """
    a, b = rng.random(n), rng.random(n)
    if rule == "uniform":
        out = a + b > 1
        a[out], b[out] = 1 - a[out], 1 - b[out]
    shrink = lambda w: (1 - EDGE_MARGIN) * w + EDGE_MARGIN / 3  # noqa: E731
    return shrink(a), shrink(b)


def points_on_faces(mesh: trimesh.Trimesh, faces: np.ndarray, rng: np.random.Generator, rule: str) -> np.ndarray:
    """(N, 3) float64 points on faces (N,) of mesh, placed by the barycentric `rule`."""
    tri = np.asarray(mesh.vertices, np.float64)[np.asarray(mesh.faces)[faces]]  # (N, 3 corners, 3)
    a, b = barycentric(rng, len(faces), rule)
    return tri[:, 0] + a[:, None] * (tri[:, 1] - tri[:, 0]) + b[:, None] * (tri[:, 2] - tri[:, 0])
