"""Directed distance field (DDF): an MLP phi(x, theta) -> distance along theta, plus visibility.

A ray (origin o, unit direction d) is answered with one network query at the
point where it enters the field box [-domain, domain]^3: t = t_entry + phi(x_e, d),
a hit when the visibility says so and the hit lies inside the box. Normals come
from one backward pass, n = grad_x phi (paper Eqs. 3 and 7), signed so n.d < 0.
The mesh (mesh_field "signed", the default) is the zero set of a signed field built from whole
lines: through a grid node x and along direction theta the network, queried once at the line's box
entry (as for a camera ray), says where the line first crosses the surface; x lies before that
crossing (s >= 0, outside or occluded) or past it (s < 0). Near the surface the lines facing it agree,
and a truncated mean over them (as in depth-map fusion) is the value (see line_vote); marching cubes
runs on a coarse-to-fine narrow band (ddfbench.extract.banded_grid) whose fine nodes query only the
mesh_keep lines their coarse parent found nearest the surface. mesh_field "udf" is the paper's
UDF(x) = min over K directions of phi(x, theta_k), taken only over directions whose visibility says
hit (paper Eq. 5), meshed as a thin shell.

cfg keys (conf/model/ddf.yaml documents each):
  network   width, depth, activation (relu | softplus), weight_norm, dropout
  inputs    direction ("vector" unit vector | "angles" polar+azimuth as in the paper),
            param ("point": x as given | "ray": x split into the foot point of its line
            and the coordinate s0 = x.d along it; the net then predicts where along the
            line the hit lies, which is constant along a ray), pos_freqs, dir_freqs
            (positional-encoding octaves; 0 = raw input)
  heads     visibility ("head": a logit trained with cross entropy | "clamp": no head,
            hit where the clamped distance stays below clamp_hit_ratio * delta, as in the paper)
  loss      loss ("l1" | "clamp" with delta), vis_weight, entry_share (share of each batch drawn
            from line_entry_labels, visibility only, half hits and half misses; none unless the
            samples give both), batch, lr, weight_decay,
            lr_schedule / lr_final_ratio / lr_warmup (ddfbench.train.Schedule), grad_clip
  mesh      mesh_field ("signed" | "udf"); signed: mesh_directions (K on the coarsest lattice),
            mesh_keep (lines per finer node), mesh_band (truncation, unit-cube units), mesh_rank
            (order statistic of |s| used as the distance bound away from the surface), mesh_coarse
            (stride of the first lattice), mesh_lipschitz (narrow-band bound);
            udf: udf_directions (K), udf_rank (1 = the min; r = the r-th smallest, robust to
            a spurious hit), udf_level_steps (level in grid steps), udf_coarse,
            udf_lipschitz (narrow band, see ddfbench.extract.banded_grid), udf_project
            (move shell vertices onto the predicted surface along -normal)
  storage   storage_dtype (float32 | float16 state dict), eval_batch
"""

from __future__ import annotations

import json
import math
import os
from typing import Any, Mapping

import numpy as np
import torch
import trimesh
from torch import nn

from ddfbench import plugins
from ddfbench.errors import InputError
from ddfbench.extract import sdf_to_mesh, udf_to_mesh
from ddfbench.geometry import FourierFeatures, ray_box
from ddfbench.representation import Budget, FitData, FitStats, Hits, Probe, RayStatus, Representation
from ddfbench.train import Schedule, seed_everything, train_loop

# Normals in intersect: a chunk whose hit share reaches this runs one backward over all its rays rather
# than a second forward + backward over its hits. Measured on CPU for the default preset (1 thread,
# 65k rays): forward with grad 0.33-0.44 s, backward 0.35-0.41 s, so one pass wins above a share of
# about backward / (forward + backward) = 0.5.
ONE_PASS_HIT_SHARE = 0.5
_CHOICES = {"activation": ("relu", "softplus"), "direction": ("vector", "angles"), "param": ("point", "ray"),
            "visibility": ("head", "clamp"), "loss": ("l1", "clamp"), "storage_dtype": ("float32", "float16"),
            "mesh_field": ("signed", "udf")}


def fibonacci_directions(k: int) -> np.ndarray:
    """k nearly uniform unit vectors (k, 3) float32 on the sphere (golden spiral)."""
    i = np.arange(k) + 0.5
    z = 1 - 2 * i / k
    r = np.sqrt(np.maximum(0.0, 1 - z * z))
    phi = math.pi * (3 - math.sqrt(5)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1).astype(np.float32)


def box_entry(origins: np.ndarray, directions: np.ndarray, half: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """geometry.ray_box against [-half, half]^3 for rays (N,3),(N,3), from t = 0 on.

    Returns t_entry (N,) (0 for origins inside), t_exit (N,), both float32, and meets (N,) bool.
    """
    enter, leave = ray_box(origins, directions, half)
    t_entry = np.maximum(enter, 0.0)
    return t_entry.astype(np.float32), leave.astype(np.float32), leave >= t_entry


def unit_normals(grad: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (N,3) from gradients (N,3), signed so n.d < 0 for unit directions (N,3), and valid (N,).

    Where the gradient vanishes or is not finite the normal falls back to -d, flagged invalid.
    """
    norm = np.linalg.norm(grad, axis=1)
    valid = np.isfinite(norm) & (norm > 1e-6)
    n = np.where(valid[:, None], grad / np.where(valid, norm, 1.0)[:, None], -directions)
    n[np.einsum("ij,ij->i", n, directions) > 0] *= -1
    return n.astype(np.float32), valid


def line_vote(s: np.ndarray, keep: int, band: float, rank: int) -> tuple[np.ndarray, np.ndarray]:
    """Signed value (N,) from line distances s (N, J) (+inf: the line misses), and the column indices
    (N, keep) of the `keep` lines nearest zero.

    Truncated mean, as in depth-map fusion: each line votes its distance clipped to +-band (a miss
    votes +band); lines that crossed the surface more than 2 band before the point (behind another
    part, or deep inside) abstain, and one extra vote of -band (a prior) makes a point with few
    votes inside. Near a surface the lines facing it agree (s ~ +-distance / cos), so a few wrong
    lines are outvoted. Where the mean passes band / 2 the value becomes the rank-th smallest |s|
    with the mean's sign: a distance bound for the narrow band.
    """
    votes = s > -2 * band
    clipped = np.where(votes, np.clip(s, -band, band), 0.0)  # misses and far-ahead lines vote +band
    mean = (clipped.sum(1) - band) / (votes.sum(1) + 1)
    r = min(int(rank), s.shape[1]) - 1
    size = np.partition(np.abs(s), r, axis=1)[:, r]
    value = np.where(np.abs(mean) < band / 2, mean, np.sign(mean) * np.maximum(np.abs(mean), size))
    order = np.argsort(np.abs(s), axis=1, kind="stable")[:, : min(int(keep), s.shape[1])]
    return value.astype(np.float32), order


def line_entry_labels(x: np.ndarray, d: np.ndarray, hit: np.ndarray, half: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact visibility labels where sample lines enter the box [-half, half]^3, the queries intersect
    and to_mesh make. From rays x (N,3), unit d (N,3), hit (N,) bool:
    a hit ray still hits from its line's entry (whatever lies between, the line meets the surface);
    a point with misses along both d and -d (the surface sampler's perpendicular pairs) lies on a
    line that misses entirely, so both its ends are misses.
    Returns (entry points (M,3) float32, directions (M,3) float32, hit (M,) bool).
    """
    miss = np.flatnonzero(~hit)
    flip = d[miss, 0] < 0  # one direction per line: the two rays of a pair share it
    line = np.concatenate([x[miss], np.where(flip[:, None], -d[miss], d[miss])], 1).astype(np.float32)
    _, inverse, count = np.unique(np.ascontiguousarray(line).view(np.dtype((np.void, 24))).ravel(),
                                  return_inverse=True, return_counts=True)
    pairs = miss[count[inverse.ravel()] == 2]
    rows = np.r_[np.flatnonzero(hit), pairs]
    xs, ds = np.asarray(x[rows], np.float32), np.asarray(d[rows], np.float32)
    back = box_entry(xs, -ds, half)[1]
    return xs - back[:, None] * ds, ds, np.asarray(hit[rows], bool)


class DDFNet(nn.Module):
    """phi(x, d) for x (N,3), unit d (N,3) -> (distance (N,), visibility logit (N,) or None)."""

    def __init__(self, cfg: Mapping[str, Any]):
        super().__init__()
        self.param, self.direction = cfg["param"], cfg["direction"]
        self.pos_pe, self.dir_pe = FourierFeatures(cfg["pos_freqs"], math.pi), FourierFeatures(cfg["dir_freqs"], math.pi)
        n_pos = self.pos_pe.out_dim(4 if self.param == "ray" else 3)
        n_dir = self.dir_pe.out_dim(3 if self.direction == "vector" else 2)
        n_out = 2 if cfg["visibility"] == "head" else 1
        act = {"relu": nn.ReLU, "softplus": lambda: nn.Softplus(beta=100)}[cfg["activation"]]
        layers, n_in = [], n_pos + n_dir
        for _ in range(int(cfg["depth"])):
            lin = nn.Linear(n_in, int(cfg["width"]))
            layers += [nn.utils.parametrizations.weight_norm(lin) if cfg["weight_norm"] else lin, act()]
            if cfg["dropout"] > 0:
                layers.append(nn.Dropout(float(cfg["dropout"])))
            n_in = int(cfg["width"])
        self.body = nn.Sequential(*layers)
        self.out = nn.Linear(n_in, n_out)

    def forward(self, x: torch.Tensor, d: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor | None]:
        if self.param == "ray":
            s0 = (x * d).sum(-1, keepdim=True)
            pos = torch.cat([x - s0 * d, s0], -1)
        else:
            pos = x
        if self.direction == "angles":
            polar = torch.acos(d[:, 2:3].clamp(-1.0, 1.0))
            dirs = torch.cat([polar, torch.atan2(d[:, 1:2], d[:, 0:1])], -1)
        else:
            dirs = d
        y = self.out(self.body(torch.cat([self.pos_pe(pos), self.dir_pe(dirs)], -1)))
        dist = y[:, 0] - s0[:, 0] if self.param == "ray" else y[:, 0]
        return dist, (y[:, 1] if y.shape[1] > 1 else None)


def _resolved(cfg: Mapping[str, Any]) -> dict[str, Any]:
    """conf/model/ddf.yaml overlaid by cfg (strict, see ddfbench.plugins), with the values checked."""
    out = plugins.family_config("ddf", cfg)
    for key, allowed in _CHOICES.items():
        if out[key] not in allowed:
            raise InputError(f"model.{key} '{out[key]}': unknown (one of {', '.join(allowed)})")
    for key in ("width", "depth", "batch", "udf_directions", "udf_rank", "eval_batch", "mesh_directions",
                "mesh_keep", "mesh_rank", "mesh_coarse"):
        if int(out[key]) < 1:
            raise InputError(f"model.{key} {out[key]}: must be a positive integer")
    if not 0.0 <= float(out["entry_share"]) < 1.0:
        raise InputError(f"model.entry_share {out['entry_share']}: must be in [0, 1)")
    for key in ("mesh_band", "mesh_lipschitz"):
        if not float(out[key]) > 0:
            raise InputError(f"model.{key} {out[key]}: must be > 0")
    if out["loss"] == "clamp" or out["visibility"] == "clamp":
        if not float(out["delta"]) > 0:
            raise InputError(f"model.delta {out['delta']}: must be > 0 for the clamp loss")
    if out["visibility"] == "clamp" and out["loss"] != "clamp":
        raise InputError("model.visibility 'clamp' needs model.loss 'clamp' (misses are learned as delta)")
    return out


class DDF(Representation):
    """The directed distance field family (see the module docstring for cfg)."""

    family = "ddf"
    sample_kind = "rays"
    learned = True
    needs_closed_surface = True  # surface sampling rejects inward rays by the odd-even rule; the mesh is a signed field

    def __init__(self, cfg: Mapping[str, Any], domain: float = 0.6):
        super().__init__(_resolved(cfg), domain)
        self.device = "cpu"
        self.net = DDFNet(self.cfg)
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

    def _vote(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """line_vote with this model's mesh_keep, mesh_band, mesh_rank."""
        c = self.cfg
        return line_vote(s, int(c["mesh_keep"]), float(c["mesh_band"]), int(c["mesh_rank"]))

    def _mesh_field(self, dirs: np.ndarray):
        """The carry field of to_mesh (see extract.banded_grid): line_vote over all directions (K,3) on
        the first lattice; finer nodes query only the mesh_keep lines their parent found nearest the
        surface (state: their direction indices, (N, mesh_keep) int16)."""

        def field(points: np.ndarray, parent: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
            idx = np.broadcast_to(np.arange(len(dirs)), (len(points), len(dirs))) if parent is None else parent
            s = self.line_distance(np.repeat(points, idx.shape[1], axis=0), dirs[idx].reshape(-1, 3)).reshape(idx.shape)
            value, order = self._vote(s)
            return value, np.take_along_axis(idx, order, axis=1).astype(np.int16)

        return field

    def to_mesh(self, resolution: int) -> trimesh.Trimesh:
        """Marching cubes of the signed line field at 0 (mesh_field "signed"), or of the UDF shell
        at udf_level_steps grid steps with shell vertices projected if udf_project ("udf", the paper)."""
        if self.cfg["mesh_field"] == "signed":
            dirs = fibonacci_directions(int(self.cfg["mesh_directions"]))
            mesh, info = sdf_to_mesh(
                self._mesh_field(dirs), int(resolution), self.domain, batch=max(1, int(self.cfg["eval_batch"]) // int(self.cfg["mesh_keep"])),
                coarse=int(self.cfg["mesh_coarse"]), lipschitz=float(self.cfg["mesh_lipschitz"]), carry=True,
            )
            self.extract_info = info
            return mesh
        dirs = fibonacci_directions(int(self.cfg["udf_directions"]))
        step = 2 * self.domain / (int(resolution) - 1)
        level = float(self.cfg["udf_level_steps"]) * step
        mesh, info = udf_to_mesh(
            lambda p: self.udf(p, dirs, int(self.cfg["udf_rank"])), int(resolution), self.domain, level,
            batch=max(1, int(self.cfg["eval_batch"]) // len(dirs)),
            coarse=int(self.cfg["udf_coarse"]), lipschitz=float(self.cfg["udf_lipschitz"]),
        )
        if not info["empty"] and self.cfg["udf_project"]:
            mesh = self._project(mesh, max_move=2 * level + step)
        self.extract_info = info
        return mesh

    def _project(self, mesh: trimesh.Trimesh, max_move: float) -> trimesh.Trimesh:
        """Move each shell vertex along -normal (towards the surface) onto the predicted hit, when close."""
        v = np.asarray(mesh.vertices, np.float32)
        towards = -np.asarray(mesh.vertex_normals, np.float32)
        dist, hit = self._forward_np(v, towards)
        move = hit & (dist <= max_move)
        v = v + np.where(move, dist, 0.0)[:, None] * towards
        return trimesh.Trimesh(v, mesh.faces, process=False)

    # ---- training -------------------------------------------------------------------------------
    def fit(self, data: FitData, budget: Budget, probe: Probe | None = None) -> FitStats:
        s = data.samples
        if s is None or s.d is None or s.t is None or s.hit is None:
            raise InputError("model ddf: needs ray samples (x, d, t, hit); the sampler gave none")
        if len(s) == 0:
            raise InputError("model ddf: the sample set is empty")
        seed_everything(budget.seed)
        self.device = budget.device
        self.net = DDFNet(self.cfg).to(self.device)
        dev = self.device
        x = torch.as_tensor(s.x, dtype=torch.float32, device=dev)
        d = torch.as_tensor(s.d, dtype=torch.float32, device=dev)
        hit = torch.as_tensor(s.hit, dtype=torch.bool, device=dev)
        t = torch.where(hit, torch.as_tensor(np.nan_to_num(s.t, posinf=0.0), dtype=torch.float32, device=dev), 0.0)
        cfg, n = self.cfg, len(s)
        gen = torch.Generator(device=dev).manual_seed(int(budget.seed))
        delta = float(cfg["delta"])
        xe, de, he = (torch.as_tensor(a, device=dev) for a in line_entry_labels(s.x, s.d, s.hit, self.domain))
        n_hit_entries = int(he.sum())
        both = 0 < n_hit_entries < len(he)  # one class alone would only bias the head: then none
        n_entry = 2 * int(round(float(cfg["entry_share"]) * int(cfg["batch"]) / 2)) if both and cfg["visibility"] == "head" else 0
        n_main = int(cfg["batch"]) - n_entry
        order = torch.argsort((~he).to(torch.uint8), stable=True)  # entry hits first, then misses
        xe, de, he = xe[order], de[order], he[order]

        def step_fn(step: int) -> torch.Tensor:
            i = torch.randint(0, n, (n_main,), device=dev, generator=gen)
            half = n_entry // 2  # as many entry hits as entry misses
            j = torch.cat([torch.randint(0, max(n_hit_entries, 1), (half,), device=dev, generator=gen),
                           torch.randint(n_hit_entries, max(len(he), n_hit_entries + 1), (half,), device=dev, generator=gen)])
            pred, logit = self.net(torch.cat([x[i], xe[j]]), torch.cat([d[i], de[j]]))
            pred, h = pred[:n_main], hit[i]
            if cfg["loss"] == "clamp":  # |clamp(y, delta) - clamp(y_hat, delta)|, misses labelled delta
                target = torch.where(h, t[i].clamp(max=delta), delta)
                dist_loss = (pred.clamp(max=delta) - target).abs()
                dist_loss = dist_loss.mean() if logit is None else dist_loss[h].sum() / h.sum().clamp_min(1)
            else:
                dist_loss = (pred - t[i]).abs()[h].sum() / h.sum().clamp_min(1)
            if logit is None:
                return dist_loss
            vis = nn.functional.binary_cross_entropy_with_logits(logit, torch.cat([h, he[j]]).float())
            return dist_loss + float(cfg["vis_weight"]) * vis

        optimizer = torch.optim.Adam(self.net.parameters(), lr=float(cfg["lr"]), weight_decay=float(cfg["weight_decay"]))
        stats = train_loop(
            self.net, optimizer, step_fn, budget, Schedule.from_cfg(cfg),
            probe_fn=(lambda: probe(self)) if probe is not None else None,
            grad_clip=float(cfg["grad_clip"]) or None, desc="ddf",
        )
        stats.extra.update(n_samples=n, hit_share=float(s.hit.mean()), n_params=self.n_params())
        return stats

    # ---- artifact -------------------------------------------------------------------------------
    def n_params(self) -> int:
        return int(sum(p.numel() for p in self.net.parameters()))

    def save(self, path: str) -> str:
        """A folder: weights.pt (state dict, storage_dtype) and config.json. Returns the folder."""
        path = path[:-3] if path.endswith(".pt") else path
        os.makedirs(path, exist_ok=True)
        dtype = torch.float16 if self.cfg["storage_dtype"] == "float16" else torch.float32
        state = {k: v.detach().to("cpu", dtype) for k, v in self.net.state_dict().items()}
        torch.save(state, os.path.join(path, "weights.pt"))
        with open(os.path.join(path, "config.json"), "w") as f:
            json.dump({"family": self.family, "domain": self.domain, "cfg": self.cfg}, f, indent=1, sort_keys=True)
        self._saved_path = path
        return path

    @classmethod
    def load(cls, path: str, domain: float = 0.6) -> "DDF":
        path = path[:-3] if path.endswith(".pt") else path
        try:
            with open(os.path.join(path, "config.json")) as f:
                meta = json.load(f)
            state = torch.load(os.path.join(path, "weights.pt"), map_location="cpu", weights_only=True)
        except (OSError, ValueError, RuntimeError) as err:
            raise InputError(f"ddf artifact '{path}': cannot be read ({err})") from err
        if meta.get("family") != cls.family:
            raise InputError(f"ddf artifact '{path}': holds family '{meta.get('family')}', not ddf")
        rep = cls(meta["cfg"], float(meta.get("domain", domain)))
        rep.net.load_state_dict({k: v.float() for k, v in state.items()})
        rep.net.eval()
        rep._saved_path = path
        return rep


FAMILY = DDF
