"""Embree on every CPU core without open3d: the oracle's embree backend in one worker process per core.

open3d's RaycastingScene runs Embree on every core itself. A machine without open3d (a GPU machine that
gets only small wheels) still has embreex, which casts on one thread and holds the GIL, so the cores are
used by processes: each builds its own scene once, and every call hands each worker a contiguous slice
of the rays through one shared-memory block (N, 7) float32 [origin, direction, t].
"""

from __future__ import annotations

import multiprocessing as mp
import os
from multiprocessing import shared_memory

import numpy as np
import trimesh

_WORKER: dict = {}  # the worker process's oracle


def _init(vertices: np.ndarray, faces: np.ndarray) -> None:
    from ddfbench.oracle import Oracle

    _WORKER["oracle"] = Oracle(trimesh.Trimesh(vertices, faces, process=False), "embree")


def _cast(job: tuple[str, int, int, int]) -> None:
    """First-hit t of rows start:stop of the shared block `name` of n rays, written into its column 6."""
    name, n, start, stop = job
    shm = shared_memory.SharedMemory(name=name)
    try:
        rays = np.ndarray((n, 7), np.float32, buffer=shm.buf)
        rays[start:stop, 6] = _WORKER["oracle"].hit_distance(rays[start:stop, :3], rays[start:stop, 3:6])
        del rays
    finally:
        shm.close()


class EmbreePool:
    """hit_distance like Oracle's (embree backend), cast by `workers` processes (default: every core).

    The workers build their scenes as the pool starts, so a first call may wait for them (the bench's untimed
    cold call); close() ends the workers."""

    def __init__(self, mesh: trimesh.Trimesh, workers: int | None = None):
        self.workers = int(workers or os.cpu_count() or 1)
        self._pool = mp.get_context("spawn").Pool(
            self.workers, _init, (np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)))

    def hit_distance(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """t (N,) float32 of the first hit of rays (N,3),(N,3) with unit directions (inf on a miss)."""
        origins, directions = np.reshape(origins, (-1, 3)), np.reshape(directions, (-1, 3))
        n = len(origins)
        if n == 0:
            return np.zeros(0, np.float32)
        shm = shared_memory.SharedMemory(create=True, size=n * 7 * 4)
        try:
            rays = np.ndarray((n, 7), np.float32, buffer=shm.buf)
            rays[:, :3], rays[:, 3:6] = origins, directions
            bounds = np.linspace(0, n, min(self.workers, n) + 1).astype(int)
            self._pool.map(_cast, [(shm.name, n, a, b) for a, b in zip(bounds[:-1], bounds[1:])])
            t = rays[:, 6].copy()
            del rays
            return t
        finally:
            shm.close()
            shm.unlink()

    def close(self) -> None:
        self._pool.terminate()
        self._pool.join()
