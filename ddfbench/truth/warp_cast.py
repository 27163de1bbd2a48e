"""Ray casting (first hits, crossing counts) and closest points with NVIDIA Warp's BVH on CPU or CUDA.

Warp's own `mesh_query_ray` is not watertight: its BVH boxes are the triangles' exact float32 bounds and
its slab test rounds, so a ray entering a cube through an edge can miss both flat boxes there and report
the far side (1 of 104 vertex/edge rays of tests/hard_cases/test_vertex_edge_rays.py). Here the BVH
(`wp.Bvh`) is built over triangle boxes padded by a few ulps, and each candidate triangle gets the
watertight test of Woop, Benthin and Wald (2013), so rays through shared edges and vertices hit. The
module compiles without FMA contraction and builds an SAH tree on every device, so CPU and CUDA answer
alike.

The optional `gpu` extra installs Warp (`pip install -e ".[gpu]"`). The oracle (`oracle.backend: warp`,
which then answers every query through Warp and needs no open3d) and the mesh family (`model.backend:
warp`) call the numpy methods (`cast`, `count_crossings`, `closest_point`); the GPU benchmark casts torch
tensors that stay on the device through `WarpCaster.cast_torch`.
"""

from __future__ import annotations

import numpy as np
import torch

from ddfbench.core.errors import InputError

_CHUNK = 1 << 22  # rays per numpy call (~150 MB of device buffers)
_NO_LIMIT = 1.0e30  # max_t of every query: the whole ray


def _warp():
    """The warp module, initialized quietly; a one-line InputError when the `gpu` extra is missing."""
    try:
        import warp as wp
    except ImportError as exc:
        raise InputError(f'ray-cast backend \'warp\': NVIDIA Warp is not installed ({exc}); '
                         f'pip install -e ".[gpu]"') from None
    if hasattr(wp.config, "log_level"):  # no init banner or compile messages, warnings still shown
        wp.config.log_level = 30
    else:  # older Warp
        wp.config.quiet = True
    wp.init()
    return wp


wp = _warp()
# No FMA contraction: the watertight test needs each edge function computed the same way in both triangles
# of an edge, so that a ray on the edge gets exactly 0 (then float64 decides). NVRTC contracts across
# statements by default (--fmad=true), Warp's CPU build only within one, so without this a CUDA cast
# could let a ray slip through a shared edge that the CPU cast hits.
wp.set_module_options({"fuse_fp": False})


@wp.func
def _woop_t(o: wp.vec3, kx: int, ky: int, kz: int, shear: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> float:
    """Distance along the ray to triangle abc by the watertight test of Woop, Benthin and Wald (JCGT 2013),
    -1 on a miss. (kx, ky, kz) and shear come from the ray direction (see _nearest_from)."""
    pa = a - o
    pb = b - o
    pc = c - o
    ax = pa[kx] - shear[0] * pa[kz]
    ay = pa[ky] - shear[1] * pa[kz]
    bx = pb[kx] - shear[0] * pb[kz]
    by = pb[ky] - shear[1] * pb[kz]
    cx = pc[kx] - shear[0] * pc[kz]
    cy = pc[ky] - shear[1] * pc[kz]
    u = cx * by - cy * bx
    v = ax * cy - ay * cx
    w = bx * ay - by * ax
    if u == 0.0 or v == 0.0 or w == 0.0:  # on an edge in float32: decide it in float64
        u = float(wp.float64(cx) * wp.float64(by) - wp.float64(cy) * wp.float64(bx))
        v = float(wp.float64(ax) * wp.float64(cy) - wp.float64(ay) * wp.float64(cx))
        w = float(wp.float64(bx) * wp.float64(ay) - wp.float64(by) * wp.float64(ax))
    if (u < 0.0 or v < 0.0 or w < 0.0) and (u > 0.0 or v > 0.0 or w > 0.0):
        return -1.0
    det = u + v + w
    if det == 0.0:
        return -1.0
    return shear[2] * (u * pa[kz] + v * pb[kz] + w * pc[kz]) / det


@wp.func
def _nearest_from(bvh: wp.uint64, points: wp.array(dtype=wp.vec3), indices: wp.array(dtype=wp.int32),
                  o: wp.vec3, d: wp.vec3, lo: float) -> tuple[float, int]:
    """The nearest triangle hit at t >= lo along the ray o + t d: (t, triangle id), (inf, -1) when none."""
    kz = int(0)  # the direction's largest axis, then the other two in a right-handed order
    if wp.abs(d[1]) > wp.abs(d[kz]):
        kz = 1
    if wp.abs(d[2]) > wp.abs(d[kz]):
        kz = 2
    kx = (kz + 1) % 3
    ky = (kx + 1) % 3
    if d[kz] < 0.0:
        kx, ky = ky, kx
    shear = wp.vec3(d[kx] / d[kz], d[ky] / d[kz], 1.0 / d[kz])
    best_t = float(_NO_LIMIT)
    best = int(-1)
    query = wp.bvh_query_ray(bvh, o, d)
    tri = int(0)
    while wp.bvh_query_next(query, tri, best_t):
        a = points[indices[3 * tri]]
        b = points[indices[3 * tri + 1]]
        c = points[indices[3 * tri + 2]]
        tt = _woop_t(o, kx, ky, kz, shear, a, b, c)
        if tt >= lo and tt < best_t:
            best_t = tt
            best = tri
    if best < 0:
        best_t = wp.inf
    return best_t, best


@wp.kernel
def _first_hit_kernel(bvh: wp.uint64, points: wp.array(dtype=wp.vec3), indices: wp.array(dtype=wp.int32),
                      origins: wp.array(dtype=wp.vec3), directions: wp.array(dtype=wp.vec3),
                      t: wp.array(dtype=wp.float32), face: wp.array(dtype=wp.int32),
                      normal: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    best_t, best = _nearest_from(bvh, points, indices, origins[i], directions[i], 0.0)
    t[i] = best_t
    face[i] = best
    if best >= 0:
        a = points[indices[3 * best]]
        normal[i] = wp.normalize(wp.cross(points[indices[3 * best + 1]] - a, points[indices[3 * best + 2]] - a))
    else:
        normal[i] = wp.vec3(0.0, 0.0, 0.0)


@wp.kernel
def _crossings_kernel(bvh: wp.uint64, points: wp.array(dtype=wp.vec3), indices: wp.array(dtype=wp.int32),
                      origins: wp.array(dtype=wp.vec3), directions: wp.array(dtype=wp.vec3), cap: int,
                      count: wp.array(dtype=wp.int32)):
    """Surface crossings along each ray: hit after hit, each next one beyond 1e-6 (1 + t) of the last, so a
    ray through a shared edge or vertex (or duplicated faces) counts once; at most `cap`."""
    i = wp.tid()
    n = int(0)
    lo = float(0.0)
    while n < cap:
        tt, tri = _nearest_from(bvh, points, indices, origins[i], directions[i], lo)
        if tri < 0:
            break
        n += 1
        lo = tt + 1.0e-6 * (1.0 + tt)
    count[i] = n


@wp.kernel
def _closest_kernel(mesh: wp.uint64, queries: wp.array(dtype=wp.vec3), closest: wp.array(dtype=wp.vec3),
                    face: wp.array(dtype=wp.int32)):
    i = wp.tid()
    q = wp.mesh_query_point_no_sign(mesh, queries[i], float(_NO_LIMIT))
    face[i] = q.face
    closest[i] = wp.mesh_eval_position(mesh, q.face, q.u, q.v)


class WarpCaster:
    """A Warp BVH over one triangle mesh on one device ("cpu" or "cuda[:k]", torch's names).

    vertices (V,3), faces (F,3); the BVH over padded triangle boxes is built once here, in float32.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, device: str = "cpu"):
        self.device = torch.device(device)
        if self.device.type == "cuda":
            if not (wp.is_cuda_available() and torch.cuda.is_available()):
                raise InputError(f"warp device '{device}': no CUDA device on this machine (use cpu)")
            if self.device.index is None:  # "cuda" -> the current device, as torch places tensors
                self.device = torch.device("cuda", torch.cuda.current_device())
        wdev = wp.device_from_torch(self.device)
        points = np.ascontiguousarray(vertices, np.float32).reshape(-1, 3)
        faces = np.ascontiguousarray(faces, np.int32).reshape(-1, 3)
        corners = points[faces]  # (F, 3, 3)
        pad = np.float32(2.0**-20) * max(1.0, float(np.abs(points).max(initial=0.0)))  # ~8 ulps at the extent
        self._points = wp.array(points, dtype=wp.vec3, device=wdev)
        self._indices = wp.array(faces.reshape(-1), dtype=wp.int32, device=wdev)
        self._lowers = wp.array(corners.min(axis=1) - pad, dtype=wp.vec3, device=wdev)
        self._uppers = wp.array(corners.max(axis=1) + pad, dtype=wp.vec3, device=wdev)
        # SAH on every device (Warp's default on CUDA is LBVH, whose queries are slower): one tree for both
        self._bvh = wp.Bvh(self._lowers, self._uppers, constructor="sah")
        wp.synchronize_device(wdev)  # built on Warp's stream; the queries launch on torch's
        self._mesh = None  # wp.Mesh for closest-point queries, built on first use

    def cast_torch(self, origins: torch.Tensor, directions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """First hits of rays (N,3),(N,3) float32 on this caster's device, unit directions.

        Returns t (N,) float32 (inf on a miss), face id (N,) int32 (-1 on a miss) and the unit face
        normal (N,3) float32 by winding order (zeros on a miss), on the same device, ordered on
        torch's current stream (no host round trip).
        """
        if origins.device != self.device:
            raise ValueError(f"rays on {origins.device}, Warp mesh on {self.device}")
        origins = origins.detach().to(torch.float32).reshape(-1, 3).contiguous()
        directions = directions.detach().to(torch.float32).reshape(-1, 3).contiguous()
        n = len(origins)
        t = torch.empty(n, dtype=torch.float32, device=origins.device)
        face = torch.empty(n, dtype=torch.int32, device=origins.device)
        normal = torch.empty((n, 3), dtype=torch.float32, device=origins.device)
        self._launch(_first_hit_kernel, n, [self._bvh.id, self._points, self._indices, _vec3(origins), _vec3(directions),
                                            wp.from_torch(t), wp.from_torch(face), _vec3(normal)])
        return t, face, normal

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """cast_torch for numpy rays (N,3),(N,3): t (N,) float32, face (N,) int64, normal (N,3) float32, on the host."""
        n = len(np.reshape(origins, (-1, 3)))
        t, face, normal = np.empty(n, np.float32), np.empty(n, np.int64), np.empty((n, 3), np.float32)
        for sl, o, d in self._chunks(origins, directions):
            t[sl], face[sl], normal[sl] = (a.cpu().numpy() for a in self.cast_torch(o, d))
        return t, face, normal

    def count_crossings(self, origins: np.ndarray, directions: np.ndarray, cap: int = 256) -> np.ndarray:
        """Surface crossings along rays (N,3),(N,3) (N,) int64, hits within 1e-6 (1 + t) of each other one
        crossing (a ray through a shared edge or vertex counts once), at most `cap` a ray."""
        out = np.empty(len(np.reshape(origins, (-1, 3))), np.int64)
        for sl, o, d in self._chunks(origins, directions):
            count = torch.empty(len(o), dtype=torch.int32, device=self.device)
            self._launch(_crossings_kernel, len(o), [self._bvh.id, self._points, self._indices, _vec3(o), _vec3(d),
                                                     int(cap), wp.from_torch(count)])
            out[sl] = count.cpu().numpy()
        return out

    def closest_point(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The closest surface point (N,3) float32 to each point (N,3) and its triangle id (N,) int64 (Warp's
        mesh_query_point_no_sign, over a wp.Mesh built on first use)."""
        if self._mesh is None:
            self._mesh = wp.Mesh(points=self._points, indices=self._indices)
            wp.synchronize_device(self._points.device)
        n = len(np.reshape(points, (-1, 3)))
        closest, face = np.empty((n, 3), np.float32), np.empty(n, np.int64)
        for sl, p in self._chunks(points):
            c = torch.empty((len(p), 3), dtype=torch.float32, device=self.device)
            f = torch.empty(len(p), dtype=torch.int32, device=self.device)
            self._launch(_closest_kernel, len(p), [self._mesh.id, _vec3(p), _vec3(c), wp.from_torch(f)])
            closest[sl], face[sl] = c.cpu().numpy(), f.cpu().numpy()
        return closest, face

    def _chunks(self, *arrays: np.ndarray):
        """(rows, the arrays' rows as float32 (M,3) tensors on this device) for at most _CHUNK rows at a time."""
        arrays = [np.ascontiguousarray(a, np.float32).reshape(-1, 3) for a in arrays]
        for s in range(0, len(arrays[0]), _CHUNK):
            sl = slice(s, min(len(arrays[0]), s + _CHUNK))
            yield (sl, *(torch.from_numpy(a[sl]).to(self.device) for a in arrays))

    def _launch(self, kernel, n: int, inputs: list) -> None:
        """kernel over n threads on this caster's device, on torch's current stream there."""
        if n == 0:
            return
        stream = wp.stream_from_torch(self.device) if self.device.type == "cuda" else None
        wp.launch(kernel, dim=n, device=wp.device_from_torch(self.device), stream=stream, inputs=inputs)


def _vec3(a: torch.Tensor):
    """A zero-copy Warp vec3 view of a contiguous float32 (N,3) tensor."""
    return wp.from_torch(a, dtype=wp.vec3)
