"""Mesh extraction of the DDF: the signed line-vote field (default) or the paper's UDF shell, marching
cubes on a coarse-to-fine narrow band (ddfbench.evaluate.extract)."""

from __future__ import annotations

import math

import numpy as np
import trimesh

from ddfbench.core.representation import Representation
from ddfbench.evaluate.extract import sdf_to_mesh, udf_to_mesh


def fibonacci_directions(k: int) -> np.ndarray:
    """k nearly uniform unit vectors (k, 3) float32 on the sphere (golden spiral)."""
    i = np.arange(k) + 0.5
    z = 1 - 2 * i / k
    r = np.sqrt(np.maximum(0.0, 1 - z * z))
    phi = math.pi * (3 - math.sqrt(5)) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1).astype(np.float32)


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


def vote(rep: Representation, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """line_vote with the DDF rep's mesh_keep, mesh_band, mesh_rank."""
    c = rep.cfg
    return line_vote(s, int(c["mesh_keep"]), float(c["mesh_band"]), int(c["mesh_rank"]))


def mesh_field(rep: Representation, dirs: np.ndarray):
    """The carry field of to_mesh (see extract.banded_grid): line_vote over all directions (K,3) on
    the first lattice; finer nodes query only the mesh_keep lines their parent found nearest the
    surface (state: their direction indices, (N, mesh_keep) int16)."""

    def field(points: np.ndarray, parent: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """Signed line-vote value (N,) float32 (normalized units, negative inside) at grid nodes (N,3), voted by
        the lines along every direction of dirs (parent None) or along the parent's kept directions (N, mesh_keep)
        indices into dirs; returns it and the indices (N, mesh_keep) int16 of this node's lines nearest zero."""
        idx = np.broadcast_to(np.arange(len(dirs)), (len(points), len(dirs))) if parent is None else parent
        s = rep.line_distance(np.repeat(points, idx.shape[1], axis=0), dirs[idx].reshape(-1, 3)).reshape(idx.shape)
        value, order = vote(rep, s)
        return value, np.take_along_axis(idx, order, axis=1).astype(np.int16)

    return field


def to_mesh(rep: Representation, resolution: int) -> tuple[trimesh.Trimesh, dict]:
    """Marching cubes of the signed line field at 0 (mesh_field "signed"), or of the UDF shell
    at udf_level_steps grid steps with shell vertices projected if udf_project ("udf", the paper);
    returns the mesh and the extraction info."""
    if rep.cfg["mesh_field"] == "signed":
        dirs = fibonacci_directions(int(rep.cfg["mesh_directions"]))
        mesh, info = sdf_to_mesh(
            mesh_field(rep, dirs), int(resolution), rep.domain, batch=max(1, int(rep.cfg["eval_batch"]) // int(rep.cfg["mesh_keep"])),
            coarse=int(rep.cfg["mesh_coarse"]), lipschitz=float(rep.cfg["mesh_lipschitz"]), carry=True,
        )
        return mesh, info
    dirs = fibonacci_directions(int(rep.cfg["udf_directions"]))
    step = 2 * rep.domain / (int(resolution) - 1)
    level = float(rep.cfg["udf_level_steps"]) * step
    mesh, info = udf_to_mesh(
        lambda p: rep.udf(p, dirs, int(rep.cfg["udf_rank"])), int(resolution), rep.domain, level,
        batch=max(1, int(rep.cfg["eval_batch"]) // len(dirs)),
        coarse=int(rep.cfg["udf_coarse"]), lipschitz=float(rep.cfg["udf_lipschitz"]),
    )
    if not info["empty"] and rep.cfg["udf_project"]:
        mesh = project(rep, mesh, max_move=2 * level + step)
    return mesh, info


def project(rep: Representation, mesh: trimesh.Trimesh, max_move: float) -> trimesh.Trimesh:
    """Move each shell vertex along -normal (towards the surface) onto the predicted hit, when close."""
    v = np.asarray(mesh.vertices, np.float32)
    towards = -np.asarray(mesh.vertex_normals, np.float32)
    dist, hit = rep._forward_np(v, towards)
    move = hit & (dist <= max_move)
    v = v + np.where(move, dist, 0.0)[:, None] * towards
    return trimesh.Trimesh(v, mesh.faces, process=False)
