"""Ground truth on the normalized mesh: first-hit distance, occupancy, signed distance, closest point.

Backends: "open3d" (RaycastingScene, Embree inside; the default), "embree"
(embreex through trimesh; first hits only, for cross-checking: its crossings, distances and
inside tests come from open3d) and "warp" (NVIDIA Warp's BVH on `device`, cpu or cuda; the optional
`gpu` extra), which answers every query itself, so a machine without open3d (a GPU machine
where only small wheels can be installed) still has the whole oracle. open3d is imported only
where it is used. The inside test: each point casts `occupancy_rays` random rays of its own and takes
the majority of their odd-even parities, so a mesh with holes still gets a sensible answer (a single
ray would flip wherever it slips through a hole). Random directions almost never graze an edge, so
with open3d the parities use its raw intersection counts; Warp counts crossings.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Iterator

import numpy as np
import trimesh

from ddfbench.core.errors import InputError

if TYPE_CHECKING:
    import open3d as o3d

_CHUNK = 1 << 22  # rays or points per backend call, caps temporary memory (~200 MB)


def full_backend() -> str:
    """The backend that answers every query on this machine: "open3d" where it is installed, else "warp"."""
    import importlib.util

    return "open3d" if importlib.util.find_spec("open3d") else "warp"


def _open3d(what: str):
    """The open3d module; a one-line InputError naming `what` needs it where it is not installed."""
    try:
        import open3d
    except ImportError as exc:
        raise InputError(f"{what}: open3d is not installed ({exc}); oracle.backend=warp answers every query "
                         "without it") from None
    return open3d


def unit_directions(directions: np.ndarray) -> np.ndarray:
    """Ray directions (N,3) as float32 unit vectors, so that every backend answers t as a distance; a zero, NaN
    or inf direction is a one-line InputError."""
    given = np.asarray(directions).reshape(-1, 3)
    with np.errstate(over="ignore"):  # a float64 beyond float32's range: normalized below from the given value
        d = _f32(given)
    off = ~(np.abs(np.einsum("ij,ij->i", d, d) - 1.0) <= 2e-6)  # unit within float32 rounding: kept bit for bit
    if off.any():  # normalized in float64 from the values as given (a float64 1e-50 or 1e39 is a direction)
        src = np.asarray(given[off], np.float64)
        norm = np.linalg.norm(src, axis=1)
        bad = ~(np.isfinite(norm) & (norm > 0))
        if bad.any():
            raise InputError(f"ray directions: {int(bad.sum())} of {len(d)} are zero, NaN or inf (a ray needs a direction)")
        d = d.copy()
        d[off] = (src / norm[:, None]).astype(np.float32)
    return d


def _f32(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32)


def open3d_scene(mesh: trimesh.Trimesh, what: str = "an open3d ray-casting scene") -> o3d.t.geometry.RaycastingScene:
    """open3d's RaycastingScene of the mesh's triangles (float32 vertices), nothing around it; a one-line
    InputError naming `what` where open3d is not installed."""
    o3d = _open3d(what)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(_f32(mesh.vertices)),
                        o3d.core.Tensor(np.ascontiguousarray(mesh.faces, dtype=np.uint32)))
    return scene


def _ray_chunks(origins: np.ndarray, directions: np.ndarray) -> Iterator[tuple[slice, o3d.core.Tensor]]:
    """Rays (N,3),(N,3) packed once in open3d's layout (N, 6) float32 [origin, direction] (casting as it
    copies), then handed out as (rows, zero-copy tensor) of at most _CHUNK rays."""
    origins, directions = np.reshape(origins, (-1, 3)), np.reshape(directions, (-1, 3))
    rays = np.empty((len(origins), 6), np.float32)
    rays[:, :3], rays[:, 3:] = origins, directions
    for s in range(0, len(rays), _CHUNK):
        yield slice(s, min(len(rays), s + _CHUNK)), _tensor(rays[s : s + _CHUNK])


def _tensor(a: np.ndarray) -> o3d.core.Tensor:
    """A zero-copy open3d view of a C-contiguous array (the tensor holds a reference to it)."""
    o3d = _open3d("this oracle query")

    return o3d.core.Tensor.from_numpy(np.ascontiguousarray(a))


class Oracle:
    """Exact queries against a triangle mesh (N rays or points at a time, float32 results).

    backend: "open3d", "embree" (first hits; the rest open3d) or "warp" (every query); occupancy_rays:
    votes per inside test (odd); device: where the warp backend runs ("cpu" | "cuda"; the others: CPU).
    """

    def __init__(self, mesh: trimesh.Trimesh, backend: str = "open3d", occupancy_rays: int = 5, device: str = "cpu"):
        if backend not in ("open3d", "embree", "warp"):
            raise ValueError(f"oracle backend '{backend}': unknown (open3d | embree | warp)")
        self.mesh = mesh
        self.backend = backend
        self.occupancy_rays = int(occupancy_rays) | 1
        self._face_normals = _f32(mesh.face_normals)
        self._o3d_scene = self._embree = self._warp = None
        if backend == "warp":
            from ddfbench.truth.warp_cast import WarpCaster

            self._warp = WarpCaster(mesh.vertices, mesh.faces, device)
        if backend == "embree":
            from trimesh.ray.ray_pyembree import RayMeshIntersector

            self._embree = RayMeshIntersector(mesh)
        if backend == "open3d":  # every query needs the scene: a missing open3d is one line here, not mid-sampling
            self._o3d_scene = open3d_scene(mesh, f"oracle backend '{backend}'")

    @property
    def _scene(self):
        """open3d's RaycastingScene of the mesh (open3d backend: built in __init__; embree: on first use of a
        query other than first hits; warp: never)."""
        if self._o3d_scene is None:
            self._o3d_scene = open3d_scene(self.mesh, f"oracle backend '{self.backend}'")
        return self._o3d_scene

    # ---- rays -------------------------------------------------------------------------------
    def first_hit(self, origins: np.ndarray, directions: np.ndarray,
                  threads: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """First hit of rays (N,3),(N,3) (directions made unit: t is a distance).

        Returns t (N,) float32 (inf on a miss), triangle id (N,) int64 (-1 on a miss) and the
        geometric face normal (N,3) float32 oriented against the ray (zeros on a miss).
        threads: open3d's casting threads (0: every core); the embree and warp backends ignore it.
        """
        directions = _f32(directions).reshape(-1, 3)  # _cast makes them unit; the sign of d.n is all used here
        t, tri, normal = self._cast(origins, directions, normals=True, threads=threads)
        facing = np.einsum("ij,ij->i", normal, directions)
        normal *= np.where(facing > 0, np.float32(-1), np.float32(1))[:, None]
        return t, tri, normal

    def hit_distance(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """t (N,) float32 of the first hit of rays (N,3),(N,3) (inf on a miss): first_hit without the normals."""
        return self._cast(origins, directions)[0]

    def _cast(self, origins: np.ndarray, directions: np.ndarray, normals: bool = False,
              threads: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """t (N,) float32 and triangle id (N,) int64 of the first hits (inf and -1 on a miss), and with
        `normals` the unit face normal (N,3) float32 as stored (zeros on a miss), else None."""
        directions = unit_directions(directions)
        n = len(np.reshape(origins, (-1, 3)))
        t = np.full(n, np.inf, np.float32)
        tri = np.full(n, -1, np.int64)
        normal = np.zeros((n, 3), np.float32) if normals else None
        if self._warp is not None:
            t, tri, normal = self._warp.cast(origins, directions)
            return t, tri, normal if normals else None
        if self._embree is None:
            from open3d.t.geometry import RaycastingScene

            for sl, rays in _ray_chunks(origins, directions):
                ans = self._scene.cast_rays(rays, nthreads=int(threads))
                t[sl] = ans["t_hit"].numpy()  # inf on a miss
                ids = ans["primitive_ids"].numpy()
                tri[sl] = np.where(ids == RaycastingScene.INVALID_ID, -1, ids.astype(np.int64))
                if normals:
                    normal[sl] = ans["primitive_normals"].numpy()  # unit face normals, zeros on a miss
            return t, tri, normal
        origins, directions = _f32(origins).reshape(-1, 3), _f32(directions).reshape(-1, 3)
        for s in range(0, n, _CHUNK):
            sl = slice(s, min(n, s + _CHUNK))
            idx_tri, idx_ray, loc = self._embree.intersects_id(
                origins[sl], directions[sl], multiple_hits=False, return_locations=True
            )
            rays = idx_ray + s
            t[rays] = np.einsum("ij,ij->i", loc - origins[rays], directions[rays])
            tri[rays] = idx_tri
            if normals:
                normal[rays] = self._face_normals[idx_tri]
        return t, tri, normal

    def count_crossings(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Number of surface crossings along each ray (N,) int64.

        open3d lists every triangle a ray touches, so a ray through a shared edge or vertex would
        count 2 to 6 times: hits on one ray whose t agree within 1e-6·(1 + t) are one crossing (Warp
        merges them the same way as it counts).
        """
        directions = unit_directions(directions)
        if self._warp is not None:
            return self._warp.count_crossings(origins, directions)
        out = np.zeros(len(np.reshape(origins, (-1, 3))), np.int64)
        for sl, rays in _ray_chunks(origins, directions):
            ans = self._scene.list_intersections(rays)
            ray_ids = ans["ray_ids"].numpy()
            t = ans["t_hit"].numpy().astype(np.float64)
            if len(t) == 0:
                continue
            # one sort key orders hits by ray, then by t (the fraction stays below 1; ids < 2^22
            # leave it ~1e-9 of resolution, far below the merge tolerance)
            order = np.argsort(ray_ids + t * (0.5 / (t.max() + 1.0)))
            ray_ids, t = ray_ids[order], t[order]
            new = np.ones(len(t), bool)
            new[1:] = (ray_ids[1:] != ray_ids[:-1]) | (np.abs(t[1:] - t[:-1]) > 1e-6 * (1.0 + t[1:]))
            out[sl] = np.bincount(ray_ids[new], minlength=sl.stop - sl.start)
        return out

    def any_hit(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Whether each ray (N,3),(N,3) meets the surface at all (N,) bool: open3d's occlusion test,
        the cheapest query (stops at the first triangle found), or Warp's first hit; embree uses open3d."""
        directions = unit_directions(directions)
        if self._warp is not None:
            return np.isfinite(self._warp.cast(origins, directions)[0])
        return np.concatenate([self._scene.test_occlusions(rays).numpy() for _, rays in _ray_chunks(origins, directions)]
                               or [np.zeros(0, bool)])

    # ---- points -----------------------------------------------------------------------------
    def _points(self, fn, points: np.ndarray, **kw) -> np.ndarray:
        p = _f32(points).reshape(-1, 3)
        out = [fn(_tensor(p[s : s + _CHUNK]), **kw).numpy() for s in range(0, len(p), _CHUNK)]
        return np.concatenate(out) if out else np.zeros(0, np.float32)

    def occupancy(self, points: np.ndarray, seed: int = 0) -> np.ndarray:
        """Inside test (N,) bool of points (N,3) in the normalized frame (any point, e.g. the field box of
        half-side 0.6): majority of the crossing parities of `occupancy_rays` rays per point.

        Every point draws its own seeded random directions: open3d's compute_occupancy reuses a few
        directions for all points, so on a mesh with holes its mistakes cluster in whole regions.
        """
        p = _f32(points).reshape(-1, 3)
        k = self.occupancy_rays
        rng = np.random.default_rng(seed)
        votes = np.zeros(len(p), np.int64)
        for s in range(0, len(p), max(1, _CHUNK // k)):
            q = p[s : s + max(1, _CHUNK // k)]
            d = rng.normal(size=(len(q) * k, 3)).astype(np.float32)
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            odd = self._raw_crossings(np.repeat(q, k, axis=0), d) % 2
            votes[s : s + len(q)] = odd.reshape(len(q), k).sum(axis=1)
        return votes * 2 > k

    def _raw_crossings(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Crossing counts (N,) for the inside test's random rays: open3d's raw intersection counts
        (cheaper than count_crossings; random directions almost never meet an edge) or Warp's."""
        if self._warp is not None:
            return self._warp.count_crossings(origins, directions)
        return np.concatenate([self._scene.count_intersections(rays).numpy()
                               for _, rays in _ray_chunks(origins, directions)] or [np.zeros(0, np.int64)])

    def unsigned_distance(self, points: np.ndarray) -> np.ndarray:
        """Exact distance to the surface (N,) float32 of points (N,3), both in the normalized frame (any point,
        e.g. the field box of half-side 0.6)."""
        if self._warp is not None:
            p = _f32(points).reshape(-1, 3)
            return np.linalg.norm(self.closest_point(p)[0] - p, axis=1).astype(np.float32)
        return self._points(self._scene.compute_distance, points).astype(np.float32)

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Exact distance (N,) float32 of points (N,3), negative inside (voted inside test, occupancy); normalized
        frame, as unsigned_distance."""
        dist = self.unsigned_distance(points)
        return np.where(self.occupancy(points), -dist, dist).astype(np.float32)

    def closest_point(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Closest surface point (N,3) float32 and its triangle id (N,) int64."""
        if self._warp is not None:
            return self._warp.closest_point(points)
        p = _f32(points).reshape(-1, 3)
        cps, ids = [], []
        for s in range(0, len(p), _CHUNK):
            ans = self._scene.compute_closest_points(_tensor(p[s : s + _CHUNK]))
            cps.append(ans["points"].numpy())
            ids.append(ans["primitive_ids"].numpy().astype(np.int64))
        if not cps:
            return np.zeros((0, 3), np.float32), np.zeros(0, np.int64)
        return np.concatenate(cps), np.concatenate(ids)
