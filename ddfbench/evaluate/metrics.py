"""Point-cloud and surface metrics (DESIGN.md conventions), KD-tree based.

Conventions: chamfer L2 is squared and summed (Kaolin): mean_a min_b‖a−b‖² + mean_b min_a‖a−b‖².
Chamfer L1 (Occupancy Networks) is ½(mean dist a→b + mean dist b→a), unsquared.
Sided distance is the squared distance of each point of a to the nearest point of b.
F-score at radius r uses unsquared distances. Units: the normalized frame (unit cube).
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ddfbench.evaluate.metric_registry import fscore, penalties


def kd_tree(points: np.ndarray) -> cKDTree:
    """A KD-tree over points (N,3), in float64; build once, query with nearest_in."""
    return cKDTree(np.asarray(points, np.float64))


def nearest_in(tree: cKDTree, a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each point of a (N,3): unsigned distance (N,) float64 to the nearest point in tree and its index."""
    return tree.query(np.asarray(a, np.float64), k=1, workers=-1)


def nearest_distance(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each point of a (N,3): unsigned distance (N,) float64 to the nearest point of b (M,3) and its index."""
    return nearest_in(kd_tree(b), a)


def chamfer_l2_of(d_ab: np.ndarray, d_ba: np.ndarray) -> float:
    """Chamfer L2 (paper Eq. 14, unit weights) from unsquared nearest distances a→b (N,) and b→a (M,):
    mean d_ab² + mean d_ba²."""
    return float((d_ab**2).mean() + (d_ba**2).mean())


def chamfer_l1_of(d_ab: np.ndarray, d_ba: np.ndarray) -> float:
    """Chamfer L1 (Occupancy Networks) from nearest distances a→b (N,) and b→a (M,): ½(mean d_ab + mean d_ba)."""
    return float(0.5 * (d_ab.mean() + d_ba.mean()))


def f_score_of(d_pred_gt: np.ndarray, d_gt_pred: np.ndarray, radius: float) -> float:
    """F = 2PR/(P+R) from unsquared nearest distances pred→GT d_pred_gt (N,) (precision P: share within
    radius) and GT→pred d_gt_pred (M,) (recall R); radius unsquared, in normalized units; 0 where P+R = 0."""
    p, r = float((d_pred_gt <= radius).mean()), float((d_gt_pred <= radius).mean())
    return 0.0 if p + r == 0 else 2 * p * r / (p + r)


def summary(values: np.ndarray) -> dict[str, float]:
    """mean, median and 95th percentile of values (N,), in their own units."""
    return {"mean": float(values.mean()), "median": float(np.median(values)), "p95": float(np.percentile(values, 95))}


EVALUATION_STREAM = 0x6576616C  # "eval": the evaluation's draws are a stream of their own (evaluation_seed)


def evaluation_seed(run_seed: int) -> int:
    """The seed of a run's evaluation points (in [0, 2^63)): derived from the run's seed on a stream of its own
    (numpy's SeedSequence of (run seed, EVALUATION_STREAM)), so the GT points do not repeat the area-weighted face
    draws of a sampler seeded with the run's seed. Records before 1.7.0 evaluated on the run's seed itself."""
    return int(np.random.SeedSequence([int(run_seed), EVALUATION_STREAM]).generate_state(1, np.uint64)[0] >> 1)


def sample_surface(mesh: trimesh.Trimesh, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """n points (n,3) area-uniform on the mesh and their face normals (n,3), reproducible from seed."""
    rng = np.random.default_rng(seed)
    v, f = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces)
    tri = v[f]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(cross, axis=1)
    face = rng.choice(len(f), size=n, p=area / area.sum())
    uv = rng.random((n, 2))
    fold = uv.sum(axis=1) > 1.0
    uv[fold] = 1.0 - uv[fold]
    t = tri[face]
    points = t[:, 0] + uv[:, :1] * (t[:, 1] - t[:, 0]) + uv[:, 1:] * (t[:, 2] - t[:, 0])
    normals = cross[face] / np.maximum(area[face], 1e-300)[:, None]
    return points, normals


def matched_normal_consistency(na: np.ndarray, nb: np.ndarray, a_to_b: np.ndarray, b_to_a: np.ndarray) -> float:
    """Normal consistency in [0, 1]: ½(mean |na·nb[a_to_b]| + mean |nb·na[b_to_a]|), the unsigned cosine between
    each point's unit normal and that of its nearest neighbour in the other cloud. na (N,3), nb (M,3) unit
    normals; a_to_b (N,) indices into b, b_to_a (M,) indices into a (nearest neighbours already found)."""
    ab = np.abs(np.einsum("ij,ij->i", na, nb[a_to_b]))
    ba = np.abs(np.einsum("ij,ij->i", nb, na[b_to_a]))
    return float(0.5 * (ab.mean() + ba.mean()))


def topology(mesh: trimesh.Trimesh) -> dict[str, Any]:
    """Whether a non-empty mesh is closed and how many pieces it has, after merging coincident vertices
    and dropping faces that repeat a vertex (zero-area slivers marching cubes can leave):
    closed (bool): every edge is shared by exactly two faces (trimesh's is_watertight; winding is not
    checked); components (int): the connected pieces, faces joined across every shared edge, a
    non-manifold one (3+ faces) too (a floater or a detached sliver is one more)."""
    merged = trimesh.Trimesh(np.asarray(mesh.vertices), np.asarray(mesh.faces), process=True)
    merged.update_faces(merged.nondegenerate_faces(height=None))
    n = len(merged.faces)
    if n == 0:
        return {"closed": False, "components": 0}
    edge, face = merged.edges_unique_inverse, merged.edges_face  # (3n,) each face edge's unique id, its face
    order = np.argsort(edge, kind="stable")
    same = edge[order][1:] == edge[order][:-1]  # consecutive face edges on one unique edge: join their faces
    a, b = face[order][:-1][same], face[order][1:][same]
    graph = coo_matrix((np.ones(len(a)), (a, b)), shape=(n, n))
    return {"closed": bool(merged.is_watertight), "components": int(connected_components(graph, directed=False)[0])}


def point_to_surface(points: np.ndarray, mesh: trimesh.Trimesh, signed: bool = False) -> np.ndarray:
    """Exact distance (N,) float64 from points (N,3) to the triangles of mesh, negative inside where signed (the
    oracle's voted inside test): an oracle of the mesh with the backend that answers every query here (open3d,
    or Warp where open3d is not installed)."""
    from ddfbench.truth.oracle import Oracle, full_backend

    oracle = Oracle(mesh, full_backend())
    return (oracle.signed_distance(points) if signed else oracle.unsigned_distance(points)).astype(np.float64)


def cloud_metrics(gt: np.ndarray, rec: np.ndarray, radii: Sequence[float]) -> dict[str, Any]:
    """Chamfer L2/L1, f-score per radius and sided distances between point clouds gt (N,3) and rec (M,3)
    (penalty_metrics if one is empty)."""
    if len(gt) == 0 or len(rec) == 0:
        return penalty_metrics(radii)
    return distance_metrics(nearest_distance(gt, rec)[0], nearest_distance(rec, gt)[0], radii)


def distance_metrics(d_gr: np.ndarray, d_rg: np.ndarray, radii: Sequence[float]) -> dict[str, Any]:
    """cloud_metrics from nearest distances already found: GT points to rec d_gr (N,), rec points to GT d_rg (M,)."""
    out: dict[str, Any] = {
        "chamfer_l2": chamfer_l2_of(d_gr, d_rg),
        "chamfer_l1": chamfer_l1_of(d_gr, d_rg),
        "fscore": {str(r): f_score_of(d_rg, d_gr, r) for r in radii},
        "sided_gt_to_rec": summary(d_gr**2),
        "sided_rec_to_gt": summary(d_rg**2),
    }
    return out


def penalty_metrics(radii: Sequence[float]) -> dict[str, Any]:
    """Metrics of an empty or failed reconstruction: every penalty the metric registry declares
    (the worst values the domain allows), an F-score penalty at each of `radii` (the radii a non-empty
    run of the same config measures: none at a registry radius the run did not ask for), flagged."""
    out = penalties()
    out["fscore"] = {str(r): fscore(float(r)).penalty for r in radii}
    out["empty_reconstruction"] = True
    return out


def geometry_metrics(
    gt: trimesh.Trimesh,
    rec: trimesh.Trimesh,
    n_points: int,
    radii: Sequence[float],
    seed: int = 0,
    noise_floor: bool = True,
    with_point_to_surface: bool = True,
) -> dict[str, Any]:
    """Every geometry metric of a reconstruction against GT, on n_points seeded samples per surface.

    An empty reconstruction (no faces or no area) gets penalty_metrics with empty_reconstruction=True.
    noise_floor: the same metrics of GT against an independent resample of GT (the metric's floor).
    """
    gt_pts, gt_n = sample_surface(gt, n_points, seed)
    gt_tree = kd_tree(gt_pts)  # each cloud's tree is built once and serves every metric
    empty = rec is None or len(rec.faces) == 0 or not np.isfinite(rec.vertices).all() or rec.area <= 0
    if empty:
        out = penalty_metrics(radii)
    else:
        rec_pts, rec_n = sample_surface(rec, n_points, seed + 1)
        d_gr, i_gr = nearest_in(kd_tree(rec_pts), gt_pts)
        d_rg, i_rg = nearest_in(gt_tree, rec_pts)
        out = distance_metrics(d_gr, d_rg, radii)
        out["normal_consistency"] = matched_normal_consistency(gt_n, rec_n, i_gr, i_rg)
        out["empty_reconstruction"] = False
        out.update(topology(rec))
        if with_point_to_surface:
            to_rec = point_to_surface(gt_pts, rec)
            signed_to_gt = point_to_surface(rec_pts, gt, signed=True)
            to_gt = np.abs(signed_to_gt)
            out["p2s_chamfer_l2"] = chamfer_l2_of(to_rec, to_gt)
            out["p2s_chamfer_l1"] = chamfer_l1_of(to_rec, to_gt)
            # > 0: the reconstruction lies outside GT on average (inflated), < 0 inside; |offset| near the
            # p2s chamfer L1 says the error is a shifted level rather than noise about the surface
            out["level_offset"] = float(signed_to_gt.mean())
    if noise_floor:
        resample, _ = sample_surface(gt, n_points, seed + 2)
        floor = distance_metrics(nearest_distance(gt_pts, resample)[0], nearest_in(gt_tree, resample)[0], radii)
        out["noise_floor"] = {"chamfer_l2": floor["chamfer_l2"], "chamfer_l1": floor["chamfer_l1"],
                              "fscore": floor["fscore"]}
    out["n_points"] = int(n_points)
    out["eval_seed"] = int(seed)
    return out
