"""Field -> triangle mesh by marching cubes (scikit-image, allow_degenerate=False).

API (stable; families call only these):

    mesh, info = sdf_to_mesh(fn, resolution, domain, batch=65536, coarse=1)         # signed field, level 0
    mesh, info = udf_to_mesh(fn, resolution, domain, level, batch=65536, coarse=1)  # unsigned field, level > 0
    mesh, info = field_to_mesh(values, domain, level)                        # a grid you already have

`fn` maps points (N, 3) float32 numpy in the normalized frame to values (N,)
(numpy or torch; it is called with at most `batch` points at a time). The grid
is resolution^3 nodes spanning [-domain, domain]^3 (spacing 2*domain/(resolution-1)).
coarse > 1 evaluates a narrow band only (see banded_grid): exact for a field whose
Lipschitz constant is at most `lipschitz` (1 for a true distance), a large saving
at high resolution.
Triangles face outward for signed fields (negative inside); for unsigned fields
they face away from the surface (the level set is a thin shell around it).

A field that never crosses the level (flat, empty, all inside/outside) gives an
empty mesh (0 vertices, 0 faces) and info["empty"] = True with a reason; never
an exception. Non-finite values are not crossings: +inf counts as far outside
(an unsigned field with nothing in sight), NaN is replaced by +inf and counted
in info["nonfinite"].

info: {"empty", "reason", "resolution", "level", "field_evals", "nonfinite", "seconds"}.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np
import torch
import trimesh
from skimage import measure

from ddfbench.errors import InputError

Field = Callable[[np.ndarray], "np.ndarray | torch.Tensor"]


def grid_axis(resolution: int, domain: float) -> np.ndarray:
    """Node coordinates (resolution,) float32 along one axis of [-domain, domain]."""
    if int(resolution) < 2:
        raise InputError(f"mesh resolution {resolution}: must be at least 2")
    return np.linspace(-domain, domain, int(resolution), dtype=np.float32)


def grid_points(resolution: int, domain: float) -> np.ndarray:
    """All grid nodes (resolution^3, 3) float32 in C order (x slowest, z fastest)."""
    a = grid_axis(resolution, domain)
    return np.stack(np.meshgrid(a, a, a, indexing="ij"), axis=-1).reshape(-1, 3)


def evaluate(fn: Field, points: np.ndarray, batch: int = 65536) -> np.ndarray:
    """fn over points (N, 3) in batches -> (N,) float32 numpy."""
    out = np.empty(len(points), np.float32)
    for s in range(0, len(points), batch):
        v = fn(points[s : s + batch])
        if isinstance(v, torch.Tensor):
            v = v.detach().float().cpu().numpy()
        out[s : s + batch] = np.asarray(v, np.float32).reshape(-1)
    return out


def empty_mesh() -> trimesh.Trimesh:
    return trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64), process=False)


def field_to_mesh(values: np.ndarray, domain: float, level: float):
    """Marching cubes of a (R, R, R) grid over [-domain, domain]^3 at `level` -> (mesh, info).

    Values above `level` are outside (SDF and UDF alike): face normals point up the field.
    """
    values = np.asarray(values, np.float32)
    if values.ndim != 3 or len(set(values.shape)) != 1:
        raise InputError(f"field grid of shape {values.shape}: must be a cube (R, R, R)")
    nan = np.isnan(values)
    values = np.where(nan, np.inf, values)
    info = {"empty": True, "reason": None, "resolution": int(values.shape[0]), "level": float(level),
            "nonfinite": int(nan.sum())}
    finite = values[np.isfinite(values)]
    if finite.size == 0 or not (values.min() < level < values.max()):
        info["reason"] = "field does not cross the level"
        return empty_mesh(), info
    # marching cubes needs finite input: put +-inf just beyond the finite range (keeps the crossing)
    span = float(finite.max() - finite.min()) + abs(level) + 1.0
    values = np.clip(values, finite.min() - span, finite.max() + span)
    spacing = 2 * domain / (values.shape[0] - 1)
    verts, faces, _, _ = measure.marching_cubes(
        values, level=level, spacing=(spacing,) * 3, allow_degenerate=False,
        gradient_direction="ascent",
    )
    if len(faces) == 0:
        info["reason"] = "marching cubes produced no faces"
        return empty_mesh(), info
    # with gradient_direction="ascent", scikit-image winds faces down the field: reverse them
    mesh = trimesh.Trimesh(verts - domain, faces[:, ::-1], process=False)
    info["empty"] = False
    return mesh, info


def banded_grid(fn: Field, resolution: int, domain: float, level: float, coarse: int = 1,
                lipschitz: float = 1.0, batch: int = 65536) -> tuple[np.ndarray, int]:
    """Field values on the (R, R, R) grid, evaluating densely only near the `level` set.

    coarse > 1 first evaluates every coarse-th node; a fine node whose nearest coarse node
    has |value - level| > lipschitz * (distance to it + one grid step) is not next to a
    crossing and takes that coarse value instead of an evaluation (the mesh is then the
    dense grid's mesh for a field with that Lipschitz bound). Returns (values (R, R, R) float32, number of points evaluated).
    """
    if int(coarse) <= 1:
        pts = grid_points(resolution, domain)
        return evaluate(fn, pts, batch).reshape((resolution,) * 3), len(pts)
    axis = grid_axis(resolution, domain)
    idx = np.unique(np.r_[np.arange(0, resolution, coarse), resolution - 1])
    ca = axis[idx]
    coarse_vals = evaluate(fn, np.stack(np.meshgrid(ca, ca, ca, indexing="ij"), -1).reshape(-1, 3), batch)
    coarse_vals = np.nan_to_num(coarse_vals.reshape((len(idx),) * 3), nan=level, posinf=np.inf)
    nearest = np.abs(np.arange(resolution)[:, None] - idx[None, :]).argmin(1)  # fine -> coarse index
    values = coarse_vals[np.ix_(nearest, nearest, nearest)]
    # a skipped node stays more than one grid step (times lipschitz) from the level, so no
    # crossing edge ever touches it and the mesh equals the dense one
    step = float(axis[1] - axis[0])
    reach = lipschitz * (np.sqrt(3) * np.abs(axis - ca[nearest]).max() + step)
    todo = np.abs(values - level) <= reach
    fine = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1)[todo]
    values[todo] = evaluate(fn, fine, batch)
    return values, int(coarse_vals.size + len(fine))


def sdf_to_mesh(fn: Field, resolution: int, domain: float, batch: int = 65536, coarse: int = 1,
                lipschitz: float = 1.0):
    """Signed field (negative inside) -> marching cubes at level 0 -> (mesh, info). See banded_grid."""
    t0 = time.perf_counter()
    values, evals = banded_grid(fn, resolution, domain, 0.0, coarse, lipschitz, batch)
    mesh, info = field_to_mesh(values, domain, 0.0)
    info.update(field_evals=evals, seconds=time.perf_counter() - t0)
    return mesh, info


def udf_to_mesh(fn: Field, resolution: int, domain: float, level: float, batch: int = 65536, coarse: int = 1,
                lipschitz: float = 1.0):
    """Unsigned field -> marching cubes at a small positive `level` (a shell around the surface)."""
    if not level > 0:
        raise InputError(f"udf level {level}: must be > 0 (an unsigned field never crosses 0)")
    t0 = time.perf_counter()
    values, evals = banded_grid(fn, resolution, domain, float(level), coarse, lipschitz, batch)
    mesh, info = field_to_mesh(values, domain, float(level))
    info.update(field_evals=evals, seconds=time.perf_counter() - t0)
    return mesh, info
