"""Gathering labelled samples chunk by chunk, under a cap on their number."""

from __future__ import annotations

from typing import Iterator

import numpy as np

from ddfbench.errors import InputError
from ddfbench.samples import Samples

RAY_SAMPLE_BYTES = 29  # x 12 + d 12 + t 4 + hit 1 (float32, bool)
SDF_SAMPLE_BYTES = 16  # x 12 + sdf 4


def chunks(n: int, size: int) -> Iterator[slice]:
    """Consecutive slices of at most `size` covering range(n)."""
    for start in range(0, n, max(1, size)):
        yield slice(start, min(n, start + size))


class Collector:
    """Accumulates (x, d, t) ray labels or (x, sdf) labels; raises once more than `cap` are gathered."""

    def __init__(self, cap: int, what: str):
        self.cap, self.what = cap, what
        self.parts: dict[str, list[np.ndarray]] = {"x": [], "d": [], "t": [], "sdf": []}
        self.n = 0

    def expect(self, n: int, kind: str) -> None:
        """Raise now if n samples of kind ("rays" | "sdf") are already more than the cap."""
        if n > self.cap:
            self._too_many(n, RAY_SAMPLE_BYTES if kind == "rays" else SDF_SAMPLE_BYTES)

    def _too_many(self, est: float, per: int) -> None:
        raise InputError(
            f"sampling: {self.what} would give about {est:.3g} samples ({est * per / 1e9:.1f} GB), over "
            f"sampling.max_samples={self.cap}; lower the sample counts or raise sampling.max_samples"
        )

    def add(self, x: np.ndarray, d: np.ndarray | None = None, t: np.ndarray | None = None,
            sdf: np.ndarray | None = None, done: float = 1.0) -> None:
        """Append N samples; `done` (0..1] is the share of the work finished, for the size estimate."""
        for k, v in (("x", x), ("d", d), ("t", t), ("sdf", sdf)):
            if v is not None:
                self.parts[k].append(np.asarray(v, np.float32))
        self.n += len(x)
        if self.n > self.cap:
            self._too_many(self.n / max(done, 1e-9), RAY_SAMPLE_BYTES if d is not None else SDF_SAMPLE_BYTES)

    def samples(self) -> Samples:
        """The gathered samples (the collector is emptied; peak memory is the total plus one array's parts)."""
        cat = {}
        for k in list(self.parts):
            parts = self.parts.pop(k)
            cat[k] = np.concatenate(parts) if parts else None
            del parts
        self.parts = {k: [] for k in cat}
        x = cat["x"] if cat["x"] is not None else np.zeros((0, 3), np.float32)
        hit = np.isfinite(cat["t"]) if cat["t"] is not None else None
        return Samples(x=x, d=cat["d"], t=cat["t"], hit=hit, sdf=cat["sdf"])
