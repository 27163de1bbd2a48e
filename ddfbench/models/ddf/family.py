"""The DDF family: queries (one network evaluation per ray at its box entry), normals, the artifact."""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np
import torch
import trimesh

from ddfbench.core.geometry import BOX_HALF, box_entry
from ddfbench.core.representation import Budget, FitData, FitStats, Hits, Probe, RayStatus, Representation
from ddfbench.models.ddf import fit as ddf_fit
from ddfbench.models.ddf import mesh as ddf_mesh
from ddfbench.models.ddf.network import DDFNet, checked_config
from ddfbench.models.ddf.rays import unit_normals

# Normals in intersect: a chunk whose hit share reaches this runs one backward over all its rays rather
# than a second forward + backward over its hits. Measured on CPU for the default preset (1 thread,
# 65k rays): forward with grad 0.33-0.44 s, backward 0.35-0.41 s, so one pass wins above a share of
# about backward / (forward + backward) = 0.5.
ONE_PASS_HIT_SHARE = 0.5


class DDF(Representation):
    """The directed distance field family (see the package docstring of ddfbench.models.ddf for cfg)."""

    family = "ddf"
    sample_kind = "rays"
    learned = True
    needs_closed_surface = True  # surface sampling rejects inward rays by the odd-even rule; the mesh is a signed field

    @classmethod
    def configure(cls, cfg: Mapping[str, Any]) -> dict[str, Any]:
        return checked_config(cfg)

    def __init__(self, cfg: Mapping[str, Any], domain: float = BOX_HALF):
        super().__init__(cfg, domain)
        self.device = "cpu"
        self.net = DDFNet(self.cfg, self.domain)
        self.net.eval()

    # ---- queries --------------------------------------------------------------------------------
    def _forward_np(self, x: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(distance >= 0, hit) for points (N,3), unit directions (N,3), in batches, no grad."""
        dist, hit = np.empty(len(x), np.float32), np.empty(len(x), bool)
        bs = int(self.cfg["eval_batch"])
        with torch.no_grad():
            for s in range(0, len(x), bs):
                xs = torch.as_tensor(np.asarray(x[s : s + bs], np.float32), device=self.device)
                ds = torch.as_tensor(np.asarray(d[s : s + bs], np.float32), device=self.device)
                t, logit = self.net(xs, ds)
                dist[s : s + bs] = t.clamp_min(0).cpu().numpy()
                hit[s : s + bs] = self._hit_from(t, logit).cpu().numpy()
        return dist, hit

    def _hit_from(self, t: torch.Tensor, logit: torch.Tensor | None) -> torch.Tensor:
        if logit is not None:
            return logit > 0
        return t < float(self.cfg["clamp_hit_ratio"]) * float(self.cfg["delta"])

    def distance(self, points: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """phi(x, theta): predicted distance (N,) float32 along unit directions (>= 0; meaningful where visible)."""
        return self._forward_np(points, directions)[0]

    def visibility(self, points: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Whether the ray from each point along its direction hits the surface (N,) bool."""
        return self._forward_np(points, directions)[1]

    def _grad_x(self, points: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """grad_x phi (N, 3) float32 by one forward with grad and one backward pass per eval_batch chunk."""
        g = np.empty((len(points), 3), np.float32)
        bs = int(self.cfg["eval_batch"])
        for s in range(0, len(points), bs):
            x = torch.as_tensor(np.asarray(points[s : s + bs], np.float32), device=self.device).requires_grad_(True)
            d = torch.as_tensor(np.asarray(directions[s : s + bs], np.float32), device=self.device)
            with torch.enable_grad():
                t, _ = self.net(x, d)
                (gs,) = torch.autograd.grad(t.sum(), x)
            g[s : s + bs] = gs.cpu().numpy()
        return g

    def normals(self, points: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit normals (N,3) from grad_x phi, signed so n.d < 0, and valid (N,) bool (see unit_normals)."""
        return unit_normals(self._grad_x(points, directions), np.asarray(directions, np.float32))

    def _accept(self, t_entry: np.ndarray, t_exit: np.ndarray, dist: np.ndarray) -> np.ndarray:
        """Which predicted hits count (N,) bool: not nearer than min_hit_distance, not beyond the box exit.
        t_entry, t_exit, dist (N,): numpy arrays or torch tensors (ddf_infer's device path), the same kind out.

        A hit predicted closer than min_hit_distance (the renderer's secondary-ray offset; a learned field is
        no more precise than that near its surface) is the surface the ray starts on; camera rays start at
        the box entry, 0.1 from any shape, so they never meet this rule.
        """
        t = t_entry + dist
        return (t > float(self.cfg["min_hit_distance"])) & (t <= t_exit)

    def _answer_with_normals(self, x: np.ndarray, d: np.ndarray, t_entry: np.ndarray, t_exit: np.ndarray):
        """Rays at their box-entry points x (N,3) along d (N,3) -> dist (N,), hit (N,), grad_x phi (N,3) (rows
        of misses undefined), field_evals, backward_passes.

        Per eval_batch chunk: one forward with grad; when at least ONE_PASS_HIT_SHARE of the chunk hits, one
        backward over the whole chunk gives every normal (the graph is already there); otherwise the graph
        is dropped and only the hits get a forward + backward (cheaper when few rays hit).
        """
        n, bs = len(x), int(self.cfg["eval_batch"])
        dist, hit, grad = np.empty(n, np.float32), np.zeros(n, bool), np.zeros((n, 3), np.float32)
        evals = backward = 0
        for s in range(0, n, bs):
            xs = torch.as_tensor(x[s : s + bs], device=self.device).requires_grad_(True)
            ds = torch.as_tensor(d[s : s + bs], device=self.device)
            with torch.enable_grad():
                t, logit = self.net(xs, ds)
            dist_s = t.detach().clamp_min(0).cpu().numpy()
            hit_s = self._hit_from(t.detach(), logit).cpu().numpy()
            hit_s &= self._accept(t_entry[s : s + bs], t_exit[s : s + bs], dist_s)
            dist[s : s + bs], hit[s : s + bs] = dist_s, hit_s
            evals += len(xs)
            if hit_s.mean() >= ONE_PASS_HIT_SHARE:
                (g,) = torch.autograd.grad(t.sum(), xs)
                grad[s : s + bs][hit_s] = g.cpu().numpy()[hit_s]
                backward += len(xs)
            elif hit_s.any():
                del t, logit
                rows = s + np.flatnonzero(hit_s)
                grad[rows] = self._grad_x(x[rows], d[rows])
                evals += len(rows)
                backward += len(rows)
        return dist, hit, grad, evals, backward

    def intersect(self, origins: np.ndarray, directions: np.ndarray, normals: bool = True) -> Hits:
        """One network query per ray at its box entry (see _accept for which hits count); with normals=True
        one backward pass gives grad_x phi (see _answer_with_normals for how the work is split).

        stats: field_evals (network point evaluations), backward_passes (points differentiated).
        """
        o, d = np.asarray(origins, np.float32).reshape(-1, 3), np.asarray(directions, np.float32).reshape(-1, 3)
        out = Hits.empty(len(o))
        t_entry, t_exit, meets = box_entry(o, d, self.domain)
        idx = np.flatnonzero(meets)
        x = (o[idx] + t_entry[idx, None] * d[idx]).astype(np.float32)
        if normals:
            dist, hit, grad, evals, backward = self._answer_with_normals(x, d[idx], t_entry[idx], t_exit[idx])
        else:
            dist, hit = self._forward_np(x, d[idx])
            hit &= self._accept(t_entry[idx], t_exit[idx], dist)
            evals, backward = len(idx), 0
        rows = idx[hit]
        out.t[rows] = t_entry[rows] + dist[hit]
        out.hit[rows] = True
        out.status[rows] = RayStatus.HIT
        if normals and len(rows):
            out.normal[rows], out.normal_valid[rows] = unit_normals(grad[hit], d[rows])
        out.stats = {"field_evals": int(evals), "backward_passes": int(backward)}
        return out

    # ---- mesh -----------------------------------------------------------------------------------
    def udf(self, points: np.ndarray, directions: np.ndarray, rank: int = 1) -> np.ndarray:
        """UDF (N,) = min over directions (K,3) of phi where visible (paper Eq. 5); inf where none hits.

        rank > 1 takes the rank-th smallest instead of the min: near a surface many directions
        see it at about the same distance, so one spurious near-zero prediction is outvoted.
        """
        k = len(directions)
        x = np.repeat(np.asarray(points, np.float32), k, axis=0)
        d = np.tile(directions, (len(points), 1))
        dist, hit = self._forward_np(x, d)
        per_dir = np.where(hit, dist, np.inf).reshape(-1, k)
        r = min(int(rank), k) - 1
        return np.partition(per_dir, r, axis=1)[:, r] if r else per_dir.min(1)

    def line_distance(self, points: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Signed distance (N,) from each point to the first surface crossing of its line along its unit
        direction (N,3), as seen from where the line enters the field box: >= 0 when the point lies
        before that crossing (the surface is that far ahead), < 0 past it, +inf where the line misses.

        One query per line, at its box entry: the same query intersect makes for a camera ray.
        """
        points, directions = np.asarray(points, np.float32), np.asarray(directions, np.float32)
        back = box_entry(points, -directions, self.domain)[1]  # distance back to the box boundary
        dist, hit = self._forward_np(points - back[:, None] * directions, directions)
        return np.where(hit, dist - back, np.inf).astype(np.float32)

    def to_mesh(self, resolution: int) -> trimesh.Trimesh:
        """See ddfbench.models.ddf.mesh.to_mesh (mesh_field "signed" or "udf")."""
        mesh, self.extract_info = ddf_mesh.to_mesh(self, resolution)
        return mesh

    # ---- training -------------------------------------------------------------------------------
    def fit(self, data: FitData, budget: Budget, probe: Probe | None = None) -> FitStats:
        """See ddfbench.models.ddf.fit.fit."""
        return ddf_fit.fit(self, data, budget, probe)

    # ---- artifact -------------------------------------------------------------------------------
    def n_params(self) -> int:
        return int(sum(p.numel() for p in self.net.parameters()))

    def save(self, path: str) -> str:
        """One file <path>.pt: the state dict in storage_dtype and a JSON header (see _save_network). The live
        network takes the stored values (float16 rounds it), so what is measured afterwards is what is shipped."""
        dtype = torch.float16 if self.cfg["storage_dtype"] == "float16" else torch.float32
        stored = {k: v.detach().to("cpu", dtype) for k, v in self.net.state_dict().items()}
        self.net.load_state_dict(stored)  # copied into the live tensors in their own dtype and device
        return self._save_network(path, stored)

    @classmethod
    def load(cls, path: str, domain: float | None = None) -> "DDF":
        header, state = cls._read_network(path)
        rep = cls(header["cfg"], cls._artifact_domain(path, header, domain))
        rep.net.load_state_dict({k: v.float() for k, v in state.items()})
        rep.net.eval()
        rep._saved_path = path
        return rep
