"""Surface sampling (the DDF paper's construction), exact labels from the oracle.

Rays: points p on the faces (s_fc per face, or an area-weighted total of the same size), s_dr
directions theta per point, s_p marching distances t along each; the sample is
(x = p + t theta, d = -theta; t). Per (p, theta) the oracle casts:

1. the crossing count of the forward ray from p + 1e-5 theta along theta: odd (the odd-even
   rule of the paper) means theta marches into the mesh, and every sample of the ray is
   rejected (`inside`); zero means the ray never re-enters;
2. where the count is even and nonzero, the forward ray's first hit: t_esc, the distance to
   the next surface;
3. one backward ray from the farthest kept sample x_far along -theta, which must hit at t_far
   (within 1e-5); otherwise the ray's samples are rejected (`verify`). Every other kept sample
   lies on that verified segment, so its label is exact too. A kept label is then the float64 distance from the
   stored float32 x back along the stored float32 d to p's face plane (labelling p + t theta in float64 and
   rounding x afterwards put the label's end up to 6e-5 off the face at grazing incidence).

Samples are rejected where t >= t_esc - 1e-5 (another part before t: `occluded`), where x lies
less than 1e-5 above p's face plane (float rounding could put it under the face: `grazing`), and
where x leaves the field box (`outside_box`). Rays that never re-enter (forward miss) also give
(x, theta; inf) and, where the oracle finds they miss, (x, +-u; inf) for a random unit u
perpendicular to theta (the paper's theta +- pi/2). Marching distances lie in [t_min, box exit].

SDF: s_dr x s_p points per surface point, p + sigma N(0, I) with sigma cycling over sdf_sigmas
(DeepSDF-style narrow band), labelled by the oracle's signed distance; points outside the box
are rejected. With sdf_uniform = f > 0, points uniform in the field box are appended after the
near-surface ones, f of all SDF labels (the near-surface labels are those of f = 0, row for row):
the narrow band alone leaves the box more than ~3 max(sdf_sigmas) from the surface unlabelled, where
the ray labels reach to the box exit.

Perpendicular rays that hit are dropped (counted as `perpendicular_hit`).

Size: s_fc*F * s_dr * s_p marching candidates (F faces); a kept step gives 1 label, on an
escaping ray up to 4. 29 bytes per ray label, 16 per SDF label. Measured on the bunny (56k
faces): the default (total, 1 x 2 x 2) gives 3.5e5 labels, 10 MB; per_face s_fc = s_dr = s_p = 10
gives 8.8e7 labels, 2.5 GB (peak resident memory 2.8 GB). Work is streamed in chunks of about 2M
candidates; more than max_samples labels (default 1e8, 2.9 GB) stop the run with an InputError.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from ddfbench.core.geometry import ray_box
from ddfbench.sampling import params
from ddfbench.sampling.box import uniform_in_box
from ddfbench.sampling.collect import Collector, chunks
from ddfbench.sampling.directions import DIRECTION_RULES, random_perpendicular
from ddfbench.sampling.samples import Samples
from ddfbench.sampling.steps import STEP_RULES, marching_distances
from ddfbench.sampling.triangles import BARYCENTRIC_RULES, FACE_MODES, face_plan, points_on_faces
from ddfbench.truth.oracle import Oracle
from ddfbench.truth.shapes import Shape

KEYS = ("face_mode", "s_fc", "s_dr", "s_p", "barycentric", "directions", "steps", "t_min",
        "perpendicular", "sdf_sigmas", "sdf_uniform", "box", "max_samples")
OFFSET = 1e-5  # forward rays leave from p + OFFSET theta, off p's own face
TOL = 1e-5  # occlusion margin, backward-check tolerance and least height above the face (unit-cube units)
CHUNK_CANDIDATES = 1 << 21
LABELS_PER_CANDIDATE = {False: 2, True: 4}  # kept step, its escape label, two perpendicular misses


def read_config(cfg: Mapping[str, Any]) -> dict[str, Any]:
    """The validated parameters of a surface config (all keys of conf/sampling/surface.yaml)."""
    params.check_keys(cfg, KEYS)
    return {
        "face_mode": params.choice(cfg, "face_mode", FACE_MODES),
        "s_fc": params.count(cfg, "s_fc"),
        "s_dr": params.count(cfg, "s_dr"),
        "s_p": params.count(cfg, "s_p"),
        "barycentric": params.choice(cfg, "barycentric", BARYCENTRIC_RULES),
        "directions": params.choice(cfg, "directions", DIRECTION_RULES),
        "steps": params.choice(cfg, "steps", STEP_RULES),
        "t_min": params.positive(cfg, "t_min"),
        "perpendicular": params.flag(cfg, "perpendicular"),
        "sdf_sigmas": params.number_list(cfg, "sdf_sigmas"),
        "sdf_uniform": params.share(cfg, "sdf_uniform"),
        "box": params.positive(cfg, "box"),
        "max_samples": params.count(cfg, "max_samples"),
    }


def sample(shape: Shape, oracle: Oracle, cfg: Mapping[str, Any], kind: str,
           rng: np.random.Generator) -> tuple[Samples, dict[str, Any], dict[str, int]]:
    """Samples of `kind` ("rays" | "sdf"), the parameters used, and rejection counts by reason."""
    p = read_config(cfg)
    faces = face_plan(shape.mesh, p["s_fc"], p["face_mode"], rng)
    per_point = p["s_dr"] * p["s_p"]
    n_cand = len(faces) * per_point
    out = Collector(p["max_samples"], f"surface sampling of {shape.name} ({n_cand} candidates)")
    n_labels = n_cand + _uniform_count(n_cand, p) if kind == "sdf" else n_cand
    out.expect(n_labels, kind, most=n_labels if kind == "sdf" else n_cand * LABELS_PER_CANDIDATE[p["perpendicular"]])
    rejected: dict[str, int] = {}
    for sl in chunks(len(faces), max(1, CHUNK_CANDIDATES // per_point)):
        pts = points_on_faces(shape.mesh, faces[sl], rng, p["barycentric"])
        if kind == "sdf":
            _near_surface_sdf(pts, p, oracle, rng, out, rejected, done=sl.stop / len(faces))
        else:
            normals = np.asarray(shape.mesh.face_normals, np.float64)[faces[sl]]
            _marching_rays(pts, normals, p, oracle, rng, out, rejected, done=sl.stop / len(faces))
    n_uniform = _uniform_count(out.n, p) if kind == "sdf" else 0
    _uniform_sdf(n_uniform, p, oracle, rng, out)
    info = dict(p, n_points=int(len(faces)), candidates=int(n_cand), uniform_labels=n_uniform)
    return out.samples(), info, rejected


def _count(rejected: dict[str, int], reason: str, n) -> None:
    rejected[reason] = rejected.get(reason, 0) + int(n)


def _marching_rays(pts, normals, p, oracle, rng, out: Collector, rejected, done: float) -> None:
    """Ray labels for surface points (P,3) with face normals (P,3): s_dr directions x s_p steps each."""
    s_dr, s_p = p["s_dr"], p["s_p"]
    base = np.repeat(pts, s_dr, axis=0)  # (R, 3) float64, R = P s_dr
    theta = DIRECTION_RULES[p["directions"]](rng, len(base)).astype(np.float64)
    cos_n = np.abs(np.einsum("ij,ij->i", np.repeat(normals, s_dr, axis=0), theta))

    origin = base + OFFSET * theta
    crossings = oracle.count_crossings(origin, theta)
    inside = crossings % 2 == 1
    reenters = (crossings > 0) & ~inside  # outward rays that hit another part
    t_esc = np.full(len(base), np.inf)
    t_esc[reenters] = oracle.hit_distance(origin[reenters], theta[reenters]).astype(np.float64) + OFFSET

    t_enter, t_exit = ray_box(base, theta, p["box"])
    t = marching_distances(p["steps"], s_p, p["t_min"], t_exit, rng)  # (R, s_p)
    grazing = t * cos_n[:, None] < TOL
    occluded = t >= t_esc[:, None] - TOL
    outside = (t > t_exit[:, None]) | (t < t_enter[:, None])
    keep = ~(inside[:, None] | grazing | occluded | outside)
    _count(rejected, "inside", inside.sum() * s_p)
    _count(rejected, "grazing", (grazing & ~inside[:, None]).sum())
    _count(rejected, "occluded", (occluded & ~grazing & ~inside[:, None]).sum())
    _count(rejected, "outside_box", (outside & ~occluded & ~grazing & ~inside[:, None]).sum())

    # one backward cast per ray from its farthest kept sample checks the whole kept segment
    rays = np.flatnonzero(keep.any(axis=1))
    t_far = np.where(keep[rays], t[rays], -np.inf).max(axis=1)
    t_back = oracle.hit_distance(base[rays] + t_far[:, None] * theta[rays], -theta[rays])
    bad = rays[~(np.abs(t_back - t_far) <= TOL)]
    _count(rejected, "verify", keep[bad].sum())
    keep[bad] = False

    r, k = np.nonzero(keep)  # ray and step of every kept sample
    th32 = theta.astype(np.float32)
    tk = t[r, k].astype(np.float32)
    th = np.take(th32, r, axis=0)
    x = np.take(base.astype(np.float32), r, axis=0) + tk[:, None] * th
    # the label of the stored float32 ray: the float64 distance from x back along th to p's face plane (rounding x
    # moves it by ~3e-8, which near grazing incidence moved the label's end off the face by up to 6e-5)
    n_r = np.take(normals, r // s_dr, axis=0)
    tk = (np.einsum("ij,ij->i", x - np.take(base, r, axis=0), n_r) / np.einsum("ij,ij->i", th.astype(np.float64), n_r)
          ).astype(np.float32)
    out.add(x, -th, tk, done=done)
    esc = crossings[r] == 0  # the ray from x along theta is a tail of a forward ray that crosses nothing
    x_esc, th_esc = x[esc], th[esc]
    out.add(x_esc, th_esc, np.full(len(x_esc), np.inf, np.float32), done=done)
    if p["perpendicular"] and len(x_esc):
        u = np.take(random_perpendicular(rng, th32), r[esc], axis=0)  # theta +- pi/2, one axis per ray
        for side in (u, -u):
            miss = ~oracle.any_hit(x_esc, side)
            _count(rejected, "perpendicular_hit", (~miss).sum())
            out.add(x_esc[miss], side[miss], np.full(int(miss.sum()), np.inf, np.float32), done=done)


def _near_surface_sdf(pts, p, oracle, rng, out: Collector, rejected, done: float) -> None:
    """SDF labels at Gaussian offsets of surface points (P,3): s_dr x s_p per point."""
    n_each = p["s_dr"] * p["s_p"]
    sigma = np.tile(np.asarray(p["sdf_sigmas"]), -(-n_each // len(p["sdf_sigmas"])))[:n_each]
    x = np.repeat(pts, n_each, axis=0) + np.tile(sigma, len(pts))[:, None] * rng.standard_normal((len(pts) * n_each, 3))
    inside_box = np.all(np.abs(x) <= p["box"], axis=1)
    _count(rejected, "outside_box", (~inside_box).sum())
    x = x[inside_box].astype(np.float32)
    out.add(x, sdf=oracle.signed_distance(x), done=done)


def _uniform_count(n_near: int, p) -> int:
    """How many uniform box points make sdf_uniform of all SDF labels beside n_near near-surface ones."""
    f = p["sdf_uniform"]
    return int(round(n_near * f / (1.0 - f)))


def _uniform_sdf(n: int, p, oracle, rng, out: Collector) -> None:
    """n SDF labels at points uniform in the field box, in chunks (none drawn when n = 0)."""
    for sl in chunks(n, CHUNK_CANDIDATES):
        x = uniform_in_box(rng, sl.stop - sl.start, p["box"])
        out.add(x, sdf=oracle.signed_distance(x))
