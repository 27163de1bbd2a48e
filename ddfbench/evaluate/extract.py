"""Field -> triangle mesh by marching cubes (scikit-image, allow_degenerate=False).

API (stable; families call only these):

    mesh, info = sdf_to_mesh(fn, resolution, domain, batch=65536, coarse=1, lipschitz=1.0, carry=False)  # level 0
    mesh, info = udf_to_mesh(fn, resolution, domain, level, batch=65536, coarse=1)  # unsigned field, level > 0
    mesh, info = field_to_mesh(values, domain, level)                        # a grid you already have

`fn` maps points (N, 3) float32 numpy in the normalized frame to values (N,)
(numpy or torch; it is called with at most `batch` points at a time). The grid
is resolution^3 nodes spanning [-domain, domain]^3 (spacing 2*domain/(resolution-1)).
coarse > 1 evaluates a narrow band only (see banded_grid): exact for a field whose
Lipschitz constant is at most `lipschitz` (1 for a true distance), a large saving
at high resolution. The band is capped at MAX_BAND_SLICES * resolution^2 nodes (a
surface's band grows as resolution^2): a field whose band would be larger is not
distance-like near its level (an untrained or flat network) and refining it would
cost a dense grid, so the remaining nodes keep their coarse parent's value and
info["capped"] = True (a coarser, flagged mesh).
Triangles face outward for signed fields (negative inside); for unsigned fields
they face away from the surface (the level set is a thin shell around it).

A field that never crosses the level (flat, empty, all inside/outside) gives an
empty mesh (0 vertices, 0 faces) and info["empty"] = True with a reason; never
an exception. Non-finite values are not crossings: +inf counts as far outside
(an unsigned field with nothing in sight), NaN is replaced by +inf and counted
in info["nonfinite"].

info: {"empty", "reason", "resolution", "level", "field_evals", "capped", "nonfinite", "seconds"}.
"""

from __future__ import annotations

import time
from typing import Callable

import numpy as np
import torch
import trimesh
from skimage import measure

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import grid_axis

Field = Callable[[np.ndarray], "np.ndarray | torch.Tensor"]

# Most nodes a banded extraction evaluates after its first lattice, in units of resolution^2. A
# trained field's band at 128^3 on the bunny held 9.2 * 128^2 nodes (the DDF's signed field, 151k).
MAX_BAND_SLICES = 20


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
    """A mesh with no vertices (0, 3) float64 and no faces (0, 3) int64: what an extraction that finds no
    surface returns (geometry_metrics scores it with the empty-reconstruction penalties)."""
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
    # marching cubes needs finite input: put +-inf just beyond the finite range (keeps the crossing), and beyond the
    # level where the infinite cells alone cross it (NaN pockets of a field wholly inside: the pockets' mesh)
    span = float(finite.max() - finite.min()) + abs(level) + 1.0
    high, low = finite.max() + span, finite.min() - span  # the field's dtype on numpy >= 2 (NEP 50), float64 on 1.x:
    # the arithmetic these bounds always had on either
    values = np.clip(values, low if low <= level else level - span, high if high >= level else level + span)
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


def _evaluate_carry(fn: Field, points: np.ndarray, parent: np.ndarray | None, batch: int):
    """fn(points, parent_state) -> (values, state) in batches -> ((N,) float32, (N, m) state)."""
    values, states = np.empty(len(points), np.float32), []
    for s in range(0, len(points), batch):
        v, st = fn(points[s : s + batch], None if parent is None else parent[s : s + batch])
        values[s : s + batch] = np.asarray(v, np.float32).reshape(-1)
        states.append(np.asarray(st))
    return values, (np.concatenate(states) if states else None)


def lattice(resolution: int, stride: int) -> np.ndarray:
    """Axis indices (K,) int of the lattice with the given stride: every stride-th node of 0..resolution-1
    and the last one."""
    return np.unique(np.r_[np.arange(0, resolution, stride), resolution - 1])


def banded_grid(fn: Field, resolution: int, domain: float, level: float, coarse: int = 1,
                lipschitz: float = 1.0, batch: int = 65536, carry: bool = False,
                max_slices: float = MAX_BAND_SLICES) -> tuple[np.ndarray, int, bool]:
    """Field values on the (R, R, R) grid, evaluated only near the `level` set, coarse to fine.

    coarse > 1: the first lattice takes every s-th node (s: coarse rounded up to a power of two);
    each finer lattice (stride s/2, ..., 1) evaluates a new node only where the bound carried from
    its nearest node of the previous lattice, |v(parent) - level| - lipschitz * |x - parent|, is not
    positive; a skipped node takes its parent's value (for a field with that Lipschitz constant,
    on the right side of the level) and the reduced bound. Last, both ends of every grid edge that
    crosses the level are evaluated (a few rounds, until none is left), so marching cubes
    interpolates true values and the mesh equals the dense grid's. NaN values always refine.
    carry=True: fn(points, parent_state) -> (values (N,), state (N, m)); parent_state is None on
    the first lattice, then each point's parent's state (a field passes down what it learned at
    a coarse node, e.g. the DDF's best directions; skipped nodes inherit it).
    max_slices: at most max_slices * R^2 nodes are evaluated after the first lattice; a lattice (or round)
    that would go past it is not evaluated and its nodes inherit, as do all finer ones (capped).
    Returns (values (R, R, R) float32, number of points evaluated, capped).
    """
    R = int(resolution)
    axis = grid_axis(R, domain)
    stride = 1
    while stride < int(coarse) and stride * 2 < R:
        stride *= 2

    def run(points, parent):
        if carry:
            return _evaluate_carry(fn, points, parent, batch)
        return evaluate(fn, points, batch), None

    def fill(go, parent_state):
        """Evaluate the nodes go (tuple of index arrays) into values, slack, state, done."""
        v, st = run(np.stack([axis[g] for g in go], -1), parent_state)
        values[go], slack[go], done[go] = v, np.nan_to_num(np.abs(v - level), nan=0.0), True
        if state is not None:
            state[go] = st
        return len(v)

    idx = lattice(R, stride)
    pts = np.stack(np.meshgrid(axis[idx], axis[idx], axis[idx], indexing="ij"), -1).reshape(-1, 3)
    v, st = run(pts, None)
    if stride == 1:
        return v.reshape((R,) * 3), len(pts), False
    values = np.zeros((R,) * 3, np.float32)
    slack = np.zeros((R,) * 3, np.float32)  # a lower bound of |field - level|, same side as the value
    done = np.zeros((R,) * 3, bool)  # evaluated, not inherited
    state = None if st is None else np.zeros((R,) * 3 + st.shape[1:], st.dtype)
    ijk = np.ix_(idx, idx, idx)
    values[ijk] = v.reshape((len(idx),) * 3)
    slack[ijk] = np.nan_to_num(np.abs(v - level), nan=0.0).reshape((len(idx),) * 3)
    done[ijk] = True
    if state is not None:
        state[ijk] = st.reshape((len(idx),) * 3 + st.shape[1:])
    step, evals = float(axis[1] - axis[0]), len(pts)
    allowance, capped = int(max_slices * R**2), False
    while stride > 1:
        prev, stride = idx, stride // 2
        idx = lattice(R, stride)
        near = prev[np.abs(idx[:, None] - prev[None, :]).argmin(1)]  # parent axis index of each node
        old = np.isin(idx, prev)
        a, b, c = np.nonzero(~(old[:, None, None] & old[None, :, None] & old[None, None, :]))
        node, parent = (idx[a], idx[b], idx[c]), (near[a], near[b], near[c])
        gap = step * np.sqrt(sum((n - p).astype(np.float32) ** 2 for n, p in zip(node, parent)))
        bound = slack[parent] - lipschitz * gap
        todo = bound <= 0
        if capped or todo.sum() > allowance:
            capped, todo = True, np.zeros_like(todo)
        skip = tuple(n[~todo] for n in node)
        values[skip] = values[tuple(p[~todo] for p in parent)]
        slack[skip] = bound[~todo]
        if state is not None:
            state[skip] = state[tuple(p[~todo] for p in parent)]
        if todo.any():
            k = fill(tuple(n[todo] for n in node), None if state is None else state[tuple(p[todo] for p in parent)])
            evals, allowance = evals + k, allowance - k
    for _ in range(3):  # ends of crossing edges that still hold an inherited value
        go = np.nonzero(_crossing_ends(values, level) & ~done)
        if capped or not len(go[0]):
            break
        if len(go[0]) > allowance:
            capped = True
            break
        k = fill(go, None if state is None else state[go])
        evals, allowance = evals + k, allowance - k
    return values, evals, capped


def _crossing_ends(values: np.ndarray, level: float) -> np.ndarray:
    """(R, R, R) bool: nodes at either end of a grid edge whose values straddle the level."""
    above = ~(values <= level)  # NaN counts as above, as in field_to_mesh
    out = np.zeros(values.shape, bool)
    for ax in range(3):
        lo, hi = [slice(None)] * 3, [slice(None)] * 3
        lo[ax], hi[ax] = slice(None, -1), slice(1, None)
        cross = above[tuple(lo)] != above[tuple(hi)]
        out[tuple(lo)] |= cross
        out[tuple(hi)] |= cross
    return out


def sdf_to_mesh(fn: Field, resolution: int, domain: float, batch: int = 65536, coarse: int = 1,
                lipschitz: float = 1.0, carry: bool = False):
    """Signed field (negative inside) -> marching cubes at level 0 -> (mesh, info). See banded_grid."""
    return _level_mesh(fn, resolution, domain, 0.0, batch, coarse, lipschitz, carry)


def udf_to_mesh(fn: Field, resolution: int, domain: float, level: float, batch: int = 65536, coarse: int = 1,
                lipschitz: float = 1.0):
    """Unsigned field fn(points (N, 3) float32) -> (N,) -> marching cubes of the (R, R, R) grid over
    [-domain, domain]^3 at a small positive `level` (normalized units: a shell around the surface)
    -> (mesh, info), as sdf_to_mesh; InputError unless level > 0."""
    if not level > 0:
        raise InputError(f"udf level {level}: must be > 0 (an unsigned field never crosses 0)")
    return _level_mesh(fn, resolution, domain, float(level), batch, coarse, lipschitz, carry=False)


def _level_mesh(fn: Field, resolution: int, domain: float, level: float, batch: int, coarse: int, lipschitz: float,
                carry: bool):
    """banded_grid then marching cubes at `level` -> (mesh, info with field_evals, capped and seconds)."""
    t0 = time.perf_counter()
    values, evals, capped = banded_grid(fn, resolution, domain, level, coarse, lipschitz, batch, carry)
    mesh, info = field_to_mesh(values, domain, level)
    info.update(field_evals=evals, capped=capped, seconds=time.perf_counter() - t0)
    return mesh, info
