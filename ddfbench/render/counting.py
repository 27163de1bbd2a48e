"""The one gate every ray query of a render passes: it asks the representation, cleans the answer
and tallies the work.

Counts (one dict per render): `<kind>_rays` for kind in primary / shadow / bounce, the work each
answer reports in Hits.stats (field_evals, backward_passes, trace_steps, and any other numeric key a
family adds, e.g. bvh_queries), intersect_calls and undecided_rays.

Cleaning makes every answer safe to shade, so no image can hold NaN: a hit needs a finite t >= 0
(anything else is a miss with t = inf); a hit normal that is missing, non-finite or near zero is
replaced by −direction (normal_valid says which); every normal faces the ray (n·d <= 0).
"""

from __future__ import annotations

import numpy as np

from ddfbench.core.representation import Hits, RayStatus, Representation

RAY_KINDS = ("primary", "shadow", "bounce")
WORK_KEYS = ("field_evals", "backward_passes", "trace_steps")


def clean_hits(hits: Hits, directions: np.ndarray, family: str) -> Hits:
    """A copy of `hits` (N rays along unit `directions` (N,3)) that is safe to shade (module docstring)."""
    n = len(directions)
    t = np.asarray(hits.t, np.float32).reshape(-1)
    hit = np.asarray(hits.hit, bool).reshape(-1)
    normal = np.asarray(hits.normal, np.float32).reshape(-1, 3) if hits.normal is not None else None
    if len(t) != n or len(hit) != n or (normal is not None and len(normal) != n):
        raise RuntimeError(f"{family}.intersect answered {len(t)} t / {len(hit)} hit values for {n} rays")
    hit = hit & np.isfinite(t) & (t >= 0)
    t = np.where(hit, t, np.float32(np.inf)).astype(np.float32)
    status = np.asarray(hits.status, np.int8).reshape(-1) if hits.status is not None else None
    if status is None or len(status) != n:
        status = np.where(hit, RayStatus.HIT, RayStatus.MISS).astype(np.int8)
    status = np.where(hit, np.int8(RayStatus.HIT), np.where(status == RayStatus.UNDECIDED, status, RayStatus.MISS))

    valid = hit.copy() if hits.normal_valid is None else hit & np.asarray(hits.normal_valid, bool).reshape(-1)
    if normal is None:
        normal, valid = np.zeros((n, 3), np.float32), np.zeros(n, bool)
    with np.errstate(invalid="ignore", over="ignore"):
        length = np.linalg.norm(normal, axis=1)
    valid &= np.isfinite(length) & (length > 1e-6)
    out = np.zeros((n, 3), np.float32)
    out[valid] = normal[valid] / length[valid, None]
    fallback = hit & ~valid
    out[fallback] = -directions[fallback]
    facing_away = np.einsum("ij,ij->i", out, directions) > 0
    out[facing_away] *= -1
    return Hits(t=t, hit=hit, normal=out, status=status.astype(np.int8), normal_valid=valid, stats=dict(hits.stats))


class CountedTracer:
    """Wraps a Representation for one render: `cast(kind, origins, directions, normals)` is the only
    way the renderer queries geometry. Queries go out in chunks of at most `chunk` rays."""

    def __init__(self, rep: Representation, chunk: int = 1 << 18):
        self.rep = rep
        self.chunk = int(chunk)
        self.counts: dict[str, int] = {f"{k}_rays": 0 for k in RAY_KINDS}
        self.counts.update({k: 0 for k in WORK_KEYS})
        self.counts.update(intersect_calls=0, undecided_rays=0)

    def cast(self, kind: str, origins: np.ndarray, directions: np.ndarray, normals: bool) -> Hits:
        """First hits of rays (N,3) origins and unit directions, tallied under `<kind>_rays` -> cleaned Hits of N
        rays (clean_hits); normals=False lets the family skip normal work (hit normals then fall back to −d)."""
        if kind not in RAY_KINDS:
            raise ValueError(f"ray kind {kind!r}: unknown ({', '.join(RAY_KINDS)})")
        origins = np.ascontiguousarray(origins, np.float32).reshape(-1, 3)
        directions = np.ascontiguousarray(directions, np.float32).reshape(-1, 3)
        n = len(origins)
        if n == 0:
            return Hits.empty(0)
        parts = []
        for s in range(0, n, self.chunk):
            sl = slice(s, min(n, s + self.chunk))
            raw = self.rep.intersect(origins[sl], directions[sl], normals=normals)
            parts.append(clean_hits(raw, directions[sl], self.rep.family))
            self._tally(raw.stats)
        hits = parts[0] if len(parts) == 1 else Hits(
            t=np.concatenate([p.t for p in parts]),
            hit=np.concatenate([p.hit for p in parts]),
            normal=np.concatenate([p.normal for p in parts]),
            status=np.concatenate([p.status for p in parts]),
            normal_valid=np.concatenate([p.normal_valid for p in parts]),
        )
        self.counts[f"{kind}_rays"] += n
        self.counts["undecided_rays"] += int(np.count_nonzero(hits.status == RayStatus.UNDECIDED))
        return hits

    def _tally(self, stats: dict) -> None:
        self.counts["intersect_calls"] += 1
        for key, value in (stats or {}).items():
            if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
                self.counts[key] = self.counts.get(key, 0) + int(value)
