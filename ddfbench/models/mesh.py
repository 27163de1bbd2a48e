"""The triangle mesh (and its LODs by quadric decimation): the reference family.

Rays are answered by Embree (open3d RaycastingScene, or embreex via the oracle's
second backend) or by NVIDIA Warp's BVH on the fit's device (`backend: warp`); storage is the size of the saved binary `.ply`.
"""

from __future__ import annotations

import time
from typing import Any, Mapping

import numpy as np
import trimesh

from ddfbench.core.atomic import write_atomic
from ddfbench.core.clock import compute_threads
from ddfbench.core.errors import InputError
from ddfbench.core.geometry import BOX_HALF
from ddfbench.core.representation import Budget, FitData, FitStats, Hits, Probe, RayStatus, Representation
from ddfbench.truth.oracle import Oracle


def decimate(mesh: trimesh.Trimesh, faces: int) -> trimesh.Trimesh:
    """Quadric edge-collapse decimation to about `faces` triangles (pymeshlab); the mesh itself if smaller."""
    if faces <= 0 or faces >= len(mesh.faces):
        return mesh
    try:
        import pymeshlab  # only LODs need it (a GPU machine may lack it: the full mesh does not)
    except ImportError as exc:
        raise InputError(f"model.faces={faces}: mesh LODs need pymeshlab, which is not installed ({exc}); "
                         "model.faces=0 is the full mesh") from None

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int32)))
    ms.meshing_decimation_quadric_edge_collapse(
        targetfacenum=int(faces), preservenormal=True, preservetopology=False, qualitythr=0.3
    )
    out = ms.current_mesh()
    return trimesh.Trimesh(out.vertex_matrix(), out.face_matrix(), process=False)


T_MIN = 1e-5  # unit-cube units (float32 ray casters: ~3e-8 at 0.5; renderer offsets are 1e-3): a hit nearer than this is the surface the ray starts on


class MeshFamily(Representation):
    """cfg: faces (0 = full resolution), backend ("open3d" | "embree" | "warp"; warp casts on the
    fit budget's device)."""

    family = "mesh"
    sample_kind = None

    def __init__(self, cfg: Mapping[str, Any], domain: float = BOX_HALF):
        super().__init__(cfg, domain)
        self.mesh: trimesh.Trimesh | None = None
        self._oracle: Oracle | None = None

    def _set_mesh(self, mesh: trimesh.Trimesh, device: str = "cpu") -> None:
        self.mesh = mesh
        self._oracle = Oracle(mesh, backend=str(self.cfg["backend"]), device=device)

    def fit(self, data: FitData, budget: Budget, probe: Probe | None = None) -> FitStats:
        start = time.perf_counter()
        self._set_mesh(decimate(data.mesh, int(self.cfg["faces"] or 0)), budget.device)
        seconds = time.perf_counter() - start
        return FitStats.built(self, seconds, {"faces": int(len(self.mesh.faces))}, probe)

    def to(self, device: str) -> "MeshFamily":
        """Cast on `device` from now on (the warp backend; open3d and embree stay on the CPU)."""
        self._set_mesh(self.mesh, device)
        return self

    def cast_threads(self) -> int | None:
        """The CPU threads this family's rays are cast on: open3d's BVH on compute_threads() (torch's, what a render
        records as render_threads), embree's on the one calling thread; None for warp (the fit's device)."""
        backend = str(self.cfg["backend"])
        return None if backend == "warp" else 1 if backend == "embree" else compute_threads()

    def intersect(self, origins: np.ndarray, directions: np.ndarray, normals: bool = True) -> Hits:
        """First hit from the oracle's ray caster (cfg.backend: open3d, embree or warp), never the surface a ray
        starts on: a hit closer than T_MIN is cast again
        from T_MIN further along (up to 3 times, doubling T_MIN, for starts that graze a facet). open3d casts on
        cast_threads() threads (what a render record states), not on every core."""
        origins = np.asarray(origins, np.float64).reshape(-1, 3)
        directions = np.asarray(directions, np.float64).reshape(-1, 3)
        threads = self.cast_threads() or 0  # open3d's count (0 would be every core); embree and warp ignore it
        t, tri, normal = self._oracle.first_hit(origins, directions, threads)
        skipped = np.zeros(len(t), np.float64)
        t_min = T_MIN
        for _ in range(3):
            again = np.flatnonzero((tri >= 0) & (t < t_min))
            if len(again) == 0:
                break
            skipped[again] += t_min
            t2, tri2, n2 = self._oracle.first_hit(origins[again] + skipped[again, None] * directions[again],
                                                  directions[again], threads)
            t[again], tri[again], normal[again] = t2, tri2, n2
            t_min *= 2
        t = np.where(tri >= 0, t + skipped, np.inf).astype(np.float32)
        hit = tri >= 0
        return Hits(
            t=t,
            hit=hit,
            normal=normal if normals else np.zeros_like(normal),
            status=np.where(hit, RayStatus.HIT, RayStatus.MISS).astype(np.int8),
            normal_valid=hit & normals,
            stats={"bvh_queries": int(len(t))},
        )

    def to_mesh(self, resolution: int) -> trimesh.Trimesh:
        return self.mesh

    def n_params(self) -> int:
        return int(self.mesh.vertices.size + self.mesh.faces.size)

    def save(self, path: str) -> str:
        if not path.endswith(".ply"):
            path = f"{path}.ply"
        self._saved_path = write_atomic(path, lambda fh: self.mesh.export(fh, file_type="ply", encoding="binary"), "wb")
        return path

    @classmethod
    def load(cls, path: str, domain: float | None = None) -> "MeshFamily":
        """The .ply written by save; a .ply stores no domain, so the caller's is used (BOX_HALF when None)."""
        rep = cls({"faces": 0}, BOX_HALF if domain is None else domain)
        rep._set_mesh(trimesh.load(path, force="mesh", process=False))
        rep._saved_path = path
        return rep


FAMILY = MeshFamily
