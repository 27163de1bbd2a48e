"""Labelled training samples, as every sampler returns them and every family reads them."""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ddfbench.core.atomic import write_atomic


@dataclass
class Samples:
    """N labelled samples in the normalized frame.

    x:   (N, 3) float32 positions.
    d:   (N, 3) float32 unit directions, or None for SDF-only samples.
    t:   (N,) float32 first-hit distance along d; inf for a miss (use `hit`, never t, in losses).
    hit: (N,) bool, t is finite.
    line_hit: (N,) bool, the whole line through x along d meets the surface (on either side of x; True
         wherever hit is), or None. Every ray sampler supplies it (sampling.build, exact by the oracle).
    sdf: (N,) float32 signed distance (negative inside), or None.
    meta: strategy parameters and counts (rejections, timings), JSON-serializable.
    """

    x: np.ndarray
    d: np.ndarray | None = None
    t: np.ndarray | None = None
    hit: np.ndarray | None = None
    line_hit: np.ndarray | None = None
    sdf: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.x.shape[0])

    def subset(self, n: int, rng: np.random.Generator) -> "Samples":
        """n samples drawn without replacement by `rng`, in their original order: every per-sample array
        (every field but meta) at the same rows."""
        if not 0 < n <= len(self):
            raise ValueError(f"subset of {n} from {len(self)} samples")
        idx = np.sort(rng.choice(len(self), size=n, replace=False))
        return dataclasses.replace(self, meta=dict(self.meta), **{
            f.name: getattr(self, f.name)[idx] for f in dataclasses.fields(self)
            if f.name != "meta" and getattr(self, f.name) is not None})

    def save_npz(self, path: str) -> None:
        """Write whole or not at all (core.atomic), so a reader never sees half a file."""
        arrays = {k: v for k in ("x", "d", "t", "hit", "line_hit", "sdf") if (v := getattr(self, k)) is not None}
        arrays["meta"] = np.array(json.dumps(self.meta))
        write_atomic(path, lambda fh: np.savez(fh, **arrays), "wb")

    @staticmethod
    def load_npz(path: str) -> "Samples":
        """Samples from an .npz written by save_npz (allow_pickle=False): arrays x (N,3) and, where saved, d (N,3),
        t (N,), hit (N,), line_hit (N,), sdf (N,), in their saved dtypes; arrays absent from the file are None,
        meta {} when the file has none."""
        with np.load(path, allow_pickle=False) as z:
            get = lambda k: z[k] if k in z.files else None  # noqa: E731
            meta = json.loads(str(z["meta"])) if "meta" in z.files else {}
            return Samples(x=z["x"], d=get("d"), t=get("t"), hit=get("hit"), line_hit=get("line_hit"), sdf=get("sdf"), meta=meta)
