"""First-hit ray casting with NVIDIA Warp's BVH on CPU or CUDA.

Warp's own `mesh_query_ray` is not watertight: its BVH boxes are the triangles' exact float32 bounds and
its slab test rounds, so a ray entering a cube through an edge can miss both flat boxes there and report
the far side (1 of 104 vertex/edge rays of tests/hard_cases/test_vertex_edge_rays.py). Here the BVH
(`wp.Bvh`) is built over triangle boxes padded by a few ulps, and each candidate triangle gets the
watertight test of Woop, Benthin and Wald (2013), so rays through shared edges and vertices hit.

The optional `gpu` extra installs Warp (`pip install -e ".[gpu]"`). The oracle (`oracle.backend: warp`)
and the mesh family (`model.backend: warp`) cast through `WarpCaster.cast` (numpy in, numpy out); the
GPU benchmark casts torch tensors that stay on the device through `WarpCaster.cast_torch`.
"""

from __future__ import annotations

import numpy as np
import torch

from ddfbench.errors import InputError

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


@wp.func
def _woop_t(o: wp.vec3, kx: int, ky: int, kz: int, shear: wp.vec3, a: wp.vec3, b: wp.vec3, c: wp.vec3) -> float:
    """Distance along the ray to triangle abc by the watertight test of Woop, Benthin and Wald (JCGT 2013),
    -1 on a miss. (kx, ky, kz) and shear come from the ray direction (see _first_hit_kernel)."""
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


@wp.kernel
def _first_hit_kernel(bvh: wp.uint64, points: wp.array(dtype=wp.vec3), indices: wp.array(dtype=wp.int32),
                      origins: wp.array(dtype=wp.vec3), directions: wp.array(dtype=wp.vec3),
                      t: wp.array(dtype=wp.float32), face: wp.array(dtype=wp.int32),
                      normal: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    o = origins[i]
    d = directions[i]
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
        if tt >= 0.0 and tt < best_t:
            best_t = tt
            best = tri
    face[i] = best
    if best >= 0:
        a = points[indices[3 * best]]
        t[i] = best_t
        normal[i] = wp.normalize(wp.cross(points[indices[3 * best + 1]] - a, points[indices[3 * best + 2]] - a))
    else:
        t[i] = wp.inf
        normal[i] = wp.vec3(0.0, 0.0, 0.0)


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
        self._bvh = wp.Bvh(self._lowers, self._uppers)

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
        if n == 0:
            return t, face, normal
        stream = wp.stream_from_torch(origins.device) if origins.device.type == "cuda" else None
        wp.launch(_first_hit_kernel, dim=n, device=wp.device_from_torch(origins.device), stream=stream,
                  inputs=[self._bvh.id, self._points, self._indices, wp.from_torch(origins, dtype=wp.vec3), wp.from_torch(directions, dtype=wp.vec3),
                          wp.from_torch(t), wp.from_torch(face), wp.from_torch(normal, dtype=wp.vec3)])
        return t, face, normal

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """cast_torch for numpy rays (N,3),(N,3): t (N,) float32, face (N,) int64, normal (N,3) float32, on the host."""
        origins = np.ascontiguousarray(origins, np.float32).reshape(-1, 3)
        directions = np.ascontiguousarray(directions, np.float32).reshape(-1, 3)
        n = len(origins)
        t, face, normal = np.empty(n, np.float32), np.empty(n, np.int64), np.empty((n, 3), np.float32)
        for s in range(0, n, _CHUNK):
            sl = slice(s, min(n, s + _CHUNK))
            ans = self.cast_torch(torch.from_numpy(origins[sl]).to(self.device),
                                  torch.from_numpy(directions[sl]).to(self.device))
            t[sl], face[sl], normal[sl] = (a.cpu().numpy() for a in ans)
        return t, face, normal
