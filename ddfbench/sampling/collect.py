"""Gathering labelled samples chunk by chunk, under a cap on their number."""

from __future__ import annotations

from typing import Iterator

import numpy as np

from ddfbench.core.errors import InputError
from ddfbench.sampling.samples import Samples

RAY_SAMPLE_BYTES = 29  # x 12 + d 12 + t 4 + hit 1 (float32, bool)
SDF_SAMPLE_BYTES = 16  # x 12 + sdf 4


def chunks(n: int, size: int) -> Iterator[slice]:
    """Consecutive slices of at most `size` covering range(n)."""
    for start in range(0, n, max(1, size)):
        yield slice(start, min(n, start + size))


class Collector:
    """Accumulates (x, d, t) ray labels or (x, sdf) labels; raises once more than `cap` are gathered.

    Labels are written straight into arrays reserved for the most the sampler can emit (see expect):
    the untouched tail of a reservation is never paged in, and samples() returns views, so no label
    is copied twice (a final concatenation of a 2.5 GB sample set cost about 6 s of page faulting).
    """

    def __init__(self, cap: int, what: str):
        self.cap, self.what = cap, what
        self.arrays: dict[str, np.ndarray] = {}
        self.rows = 0  # rows reserved per array
        self.n = 0

    def expect(self, n: int, kind: str, most: int | None = None) -> None:
        """Raise now if n samples of kind ("rays" | "sdf") are already more than the cap; reserve room for
        `most` (default n) samples, the most the sampler can emit (more still fits: the arrays grow)."""
        if n > self.cap:
            self._too_many(n, RAY_SAMPLE_BYTES if kind == "rays" else SDF_SAMPLE_BYTES)
        self.rows = max(self.rows, min(self.cap, n if most is None else most))

    def _too_many(self, est: float, per: int) -> None:
        raise InputError(
            f"sampling: {self.what} would give about {est:.3g} samples ({est * per / 1e9:.1f} GB), over "
            f"sampling.max_samples={self.cap}; lower the sample counts or raise sampling.max_samples"
        )

    def _room(self, n_total: int, fields: dict[str, np.ndarray]) -> None:
        """Make every field's array hold n_total rows (new fields start empty, full ones double)."""
        if n_total > self.rows:
            self.rows = min(self.cap, max(n_total, 2 * self.rows))
        for k, v in fields.items():
            have = self.arrays.get(k)
            if have is None or len(have) < self.rows:
                grown = np.empty((self.rows,) + v.shape[1:], np.float32)
                if have is not None:
                    grown[: self.n] = have[: self.n]
                self.arrays[k] = grown

    def add(self, x: np.ndarray, d: np.ndarray | None = None, t: np.ndarray | None = None,
            sdf: np.ndarray | None = None, done: float = 1.0) -> None:
        """Append N samples: points x (N, 3), unit directions d (N, 3), hit distances t (N,) (inf: a miss),
        signed distances sdf (N,), float32 unit-cube units, each kind only if this collector holds it;
        `done` (0..1] is the share of the work finished, for the size estimate."""
        n_total = self.n + len(x)
        if n_total > self.cap:
            self._too_many(n_total / max(done, 1e-9), RAY_SAMPLE_BYTES if d is not None else SDF_SAMPLE_BYTES)
        fields = {k: v for k, v in (("x", x), ("d", d), ("t", t), ("sdf", sdf)) if v is not None}
        self._room(n_total, fields)
        for k, v in fields.items():
            self.arrays[k][self.n : n_total] = v
        self.n = n_total

    def samples(self) -> Samples:
        """The gathered samples: views of the collector's arrays (the collector is emptied)."""
        got = {k: v[: self.n] for k, v in self.arrays.items()}
        self.arrays, self.n = {}, 0
        x = got.get("x", np.zeros((0, 3), np.float32))
        t = got.get("t")
        return Samples(x=x, d=got.get("d"), t=t, hit=None if t is None else np.isfinite(t), sdf=got.get("sdf"))
