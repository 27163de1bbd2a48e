"""Signed-distance grids of a mesh: exact everywhere, or exact in a narrow band plus fast sweeping.

Grid convention (as ddfbench.evaluate.extract): n^3 nodes spanning [-domain, domain]^3, spacing
h = 2*domain/(n-1); grid[i, j, k] is the value at (x_i, y_j, z_k), x_i = -domain + i*h.
Signed distance is negative inside.

`levelset_sdf_grid` builds the grid "via level set":

1. Narrow band, exact: a coarse-to-fine search finds every node within `band` of the
   surface without querying the whole grid. A node within distance B of the surface
   has a node of the lattice with twice the spacing s within s*h*sqrt(3)/2 of it, whose
   distance is at most B + s*h*sqrt(3)/2; so from the coarsest lattice down, only the
   27 neighbours of nodes passing that bound are queried (oracle.unsigned_distance).
   Every queried node keeps its exact distance and is frozen.
2. Outside the band, the unsigned distance solves |grad u| = 1 by fast sweeping
   (Zhao 2005): Godunov upwind updates, Gauss-Seidel, 8 sweep orderings per round.
   Each ordering visits the hyperplanes i+j+k = const in turn; the nodes of one
   hyperplane do not neighbour each other, so each is one vectorized update
   (the parallel ordering of Detrixhe et al. 2013).
3. Sign from the oracle's voted inside test: queried at every node within `band` (at
   least one grid step, so every grid edge the surface crosses has both ends in it); the
   rest of the grid splits into connected components (6-neighbour) separated by it, and
   each component takes the majority of `sign_votes` of its nodes. A component whose
   votes disagree (a mesh with a hole wider than the band joins inside and outside)
   is tested node by node.

`exact_sdf_grid` queries oracle.signed_distance at every node (the brute-force reference).
"""

from __future__ import annotations

import time

import numpy as np
from scipy import ndimage

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import grid_axis, grid_points

_FAR = np.float32(1e10)  # "not reached yet" in fast sweeping (finite, so squares stay finite in float32)


def node_points(index: np.ndarray, n: int, domain: float) -> np.ndarray:
    """Coordinates (M, 3) float32 of nodes given as (M, 3) integer indices."""
    return grid_axis(n, domain)[index]


def exact_sdf_grid(oracle, n: int, domain: float) -> np.ndarray:
    """Brute force: oracle.signed_distance at all n^3 nodes -> (n, n, n) float32."""
    return oracle.signed_distance(grid_points(n, domain)).reshape(n, n, n).astype(np.float32)


def narrow_band(oracle, n: int, domain: float, band: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact unsigned distance at (at least) every node within `band` of the surface.

    Returns (dist (n, n, n) float32 with +inf where not queried, queried (n, n, n) bool).
    """
    h = 2.0 * domain / (n - 1)
    dist = np.full((n, n, n), np.inf, np.float32)
    queried = np.zeros((n, n, n), bool)
    stride = 1
    while stride * 8 <= n - 1:
        stride *= 2
    # coarsest lattice: every stride-th node (and the last one)
    axis = np.unique(np.r_[np.arange(0, n, stride), n - 1])
    nodes = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    offsets = np.stack(np.meshgrid(*[np.array([-1, 0, 1])] * 3, indexing="ij"), -1).reshape(-1, 3)
    while True:
        new = nodes[~queried[tuple(nodes.T)]]
        dist[tuple(new.T)] = oracle.unsigned_distance(node_points(new, n, domain))
        queried[tuple(new.T)] = True
        if stride == 1:
            return dist, queried
        reach = band + np.sqrt(3.0) * h * (stride - 1)  # B_l = band + sqrt(3) h (2^l - 1)
        keep = nodes[dist[tuple(nodes.T)] <= reach]
        stride //= 2
        children = (keep[:, None, :] + stride * offsets[None]).reshape(-1, 3)
        children = np.clip(children, 0, n - 1)
        flat = np.unique(np.ravel_multi_index(tuple(children.T), (n, n, n)))
        nodes = np.stack(np.unravel_index(flat, (n, n, n)), -1)


def fast_sweep(dist: np.ndarray, frozen: np.ndarray, h: float, rounds: int = 2, tol: float = 1e-7) -> tuple[np.ndarray, int]:
    """Solve |grad u| = 1 for the non-frozen nodes of an (n, n, n) grid; frozen values are boundary data.

    Up to `rounds` rounds of 8 Gauss-Seidel sweeps; stops early when a round changes no
    value by more than tol*h (the last allowed round skips that bookkeeping). Returns
    (u (n, n, n) float32, rounds run).
    """
    n = dist.shape[0]
    m = n + 2
    u = np.full((m, m, m), _FAR, np.float32)  # one padding layer: neighbours always exist
    u[1:-1, 1:-1, 1:-1] = np.where(frozen, dist, _FAR)
    free = np.flatnonzero(~frozen)  # row-major flat indices of the unpadded grid
    i, rest = np.divmod(free, n * n)
    j, k = np.divmod(rest, n)
    del rest
    flat = ((i + 1) * m + j + 1) * m + k + 1  # the same nodes in the padded grid (intp: no cast per gather)
    del free
    ijk = [a.astype(np.int16) for a in (i, j, k)]
    del i, j, k
    h = np.float32(h)
    strides = (m * m, m, 1)
    done = 0
    for r in range(rounds):
        last = r == rounds - 1
        change = 0.0
        for flips in ((0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)):
            key = sum((n - 1 - c) if f else c for c, f in zip(ijk, flips))  # int16 hyperplane number
            order = np.argsort(key, kind="stable")
            levels = np.split(flat[order], np.cumsum(np.bincount(key, minlength=3 * n - 2))[:-1])
            del key, order
            for sequence in (levels, levels[::-1]):  # an ordering and its opposite
                for idx in sequence:
                    if idx.size:
                        change = max(change, _godunov_update(u, idx, strides, h, track=not last))
        done += 1
        if not last and change <= tol * float(h):
            break
    return u[1:-1, 1:-1, 1:-1].copy(), done


def _godunov_update(u: np.ndarray, idx: np.ndarray, strides: tuple[int, int, int], h: np.float32,
                    track: bool = True) -> float:
    """One upwind update of the flat nodes idx of the padded grid u (in place); returns the largest
    decrease (0 when not `track`ed)."""
    flat_u = u.reshape(-1)
    a = [np.minimum(flat_u[idx - s], flat_u[idx + s]) for s in strides]
    lo, hi = np.minimum(a[0], a[1]), np.maximum(a[0], a[1])
    a1 = np.minimum(lo, a[2])
    a2 = np.maximum(lo, np.minimum(hi, a[2]))
    a3 = np.maximum(hi, a[2])
    new = a1 + h
    two = 0.5 * (a1 + a2 + np.sqrt(np.maximum(2 * h * h - (a1 - a2) ** 2, 0)))
    new = np.where(new > a2, two, new)
    s = a1 + a2 + a3
    three = (s + np.sqrt(np.maximum(s * s - 3 * (a1 * a1 + a2 * a2 + a3 * a3 - h * h), 0))) / 3
    new = np.where(new > a3, three, new)
    old = flat_u[idx]
    better = np.minimum(old, new)
    flat_u[idx] = better
    if not track:
        return 0.0
    dec = old - better
    dec = dec[old < _FAR]
    return float(dec.max()) if dec.size else 0.0


def component_signs(oracle, band_nodes: np.ndarray, n: int, domain: float, votes: int, seed: int = 0) -> tuple[np.ndarray, int]:
    """Inside test for every node: voted oracle occupancy on band nodes, per-component majority elsewhere.

    Returns (inside (n, n, n) bool, number of occupancy queries).
    """
    inside = np.zeros((n, n, n), bool)
    inside[band_nodes] = oracle.occupancy(node_points(np.argwhere(band_nodes), n, domain))
    queries = int(band_nodes.sum())
    labels, count = ndimage.label(~band_nodes)
    if count == 0:
        return inside, queries
    flat_labels = labels.reshape(-1)
    order = np.argsort(flat_labels, kind="stable")
    bounds = np.r_[0, np.cumsum(np.bincount(flat_labels, minlength=count + 1))]
    rng = np.random.default_rng(seed)
    flat_inside = inside.reshape(-1)
    for c in range(1, count + 1):
        members = order[bounds[c]:bounds[c + 1]]
        pick = rng.choice(members, size=min(votes, members.size), replace=False)
        occ = oracle.occupancy(node_points(np.stack(np.unravel_index(pick, (n, n, n)), -1), n, domain))
        queries += pick.size
        if occ.all() or not occ.any():
            flat_inside[members] = bool(occ[0])
        else:
            flat_inside[members] = oracle.occupancy(node_points(np.stack(np.unravel_index(members, (n, n, n)), -1), n, domain))
            queries += members.size
    return inside, queries


def levelset_sdf_grid(oracle, n: int, domain: float, band_cells: float = 2.0, rounds: int = 1,
                      sign_votes: int = 9) -> tuple[np.ndarray, dict]:
    """Signed distance (n, n, n) float32: exact narrow band + fast sweeping + component signs.

    band_cells: half-width of the exact band in grid steps. Returns (grid, info) with
    info = {exact_nodes, sweep_rounds, occupancy_queries, seconds_band, seconds_sweep, seconds_sign}.
    """
    if band_cells < 1.0:
        raise InputError(f"grid band_cells {band_cells}: must be at least 1 (the cells the surface crosses)")
    h = 2.0 * domain / (n - 1)
    t0 = time.perf_counter()
    dist, queried = narrow_band(oracle, n, domain, band_cells * h)
    t1 = time.perf_counter()
    unsigned, done = fast_sweep(dist, queried, h, rounds=rounds)
    t2 = time.perf_counter()
    inside, queries = component_signs(oracle, dist <= band_cells * h, n, domain, sign_votes)
    t3 = time.perf_counter()
    info = {"exact_nodes": int(queried.sum()), "sweep_rounds": done, "occupancy_queries": queries,
            "seconds_band": t1 - t0, "seconds_sweep": t2 - t1, "seconds_sign": t3 - t2}
    return np.where(inside, -unsigned, unsigned).astype(np.float32), info
