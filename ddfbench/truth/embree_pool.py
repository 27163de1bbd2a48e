"""Embree on every CPU core without open3d: the oracle's embree backend in one worker process per core.

open3d's RaycastingScene runs Embree on every core itself. A machine without open3d (a GPU machine that
gets only small wheels) still has embreex, which casts on one thread and holds the GIL, so the cores are
used by processes: each builds its own scene once, and every call hands each worker a contiguous slice
of the rays through one shared-memory block of BLOCK rows (BLOCK, 7) float32 [origin, direction, t],
reused call after call (a larger call goes through it block by block, so /dev/shm needs only ~29 MB).
"""

from __future__ import annotations

import multiprocessing as mp
import os
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import shared_memory

import numpy as np
import trimesh

BLOCK = 1 << 20  # rays per pass through the shared block
STARTUP_S = 300.0  # longest wait for every worker to start (imports, scene build); then BrokenBarrierError
_WORKER: dict = {}  # the worker process's oracle


def _init(vertices: np.ndarray, faces: np.ndarray, barrier) -> None:
    from ddfbench.truth.oracle import Oracle

    _WORKER["oracle"] = Oracle(trimesh.Trimesh(vertices, faces, process=False), "embree")
    _WORKER["barrier"] = barrier


def _ready(_: int) -> int:
    """Wait until every worker holds one of these jobs (each has started and built its scene); its pid."""
    _WORKER["barrier"].wait(timeout=STARTUP_S)
    return os.getpid()


def _cast(job: tuple[str, int, int]) -> None:
    """First-hit t of rows start:stop of the shared block `name`, written into its column 6."""
    name, start, stop = job
    shm = shared_memory.SharedMemory(name=name)
    try:
        rays = np.ndarray((BLOCK, 7), np.float32, buffer=shm.buf)
        rays[start:stop, 6] = _WORKER["oracle"].hit_distance(rays[start:stop, :3], rays[start:stop, 3:6])
        del rays
    finally:
        shm.close()


class EmbreePool:
    """hit_distance like Oracle's (embree backend), cast by `workers` processes (default: the cores this process
    may run on). A worker that fails to start or dies ends the call with BrokenProcessPool, never a hang.

    The constructor returns once every worker has started and built its scene (pids: their process ids): on
    an H100 machine's 16 cores a pool still starting made the first timed calls ~30x slower than later ones
    (reports/bench/cuda/README.md). close() ends the workers and frees the block."""

    def __init__(self, mesh: trimesh.Trimesh, workers: int | None = None):
        from ddfbench.truth.oracle import Oracle

        Oracle(mesh, "embree")  # a broken embreex fails here, in this process, with its own message
        self.workers = int(workers or (len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()))
        ctx = mp.get_context("spawn")
        self._pool = ProcessPoolExecutor(self.workers, ctx, _init, (np.asarray(mesh.vertices, np.float64),
                                                                    np.asarray(mesh.faces, np.int64), ctx.Barrier(self.workers)))
        try:
            self.pids = set(self._pool.map(_ready, range(self.workers)))
        except BaseException:  # a worker that died or never came (BrokenBarrierError), or a stop: no pool left behind
            self._pool.shutdown(wait=False, cancel_futures=True)
            raise
        self._shm = shared_memory.SharedMemory(create=True, size=BLOCK * 7 * 4)
        self._rays = np.ndarray((BLOCK, 7), np.float32, buffer=self._shm.buf)

    def hit_distance(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """t (N,) float32 of the first hit of rays (N,3),(N,3) with unit directions (inf on a miss)."""
        origins, directions = np.reshape(origins, (-1, 3)), np.reshape(directions, (-1, 3))
        t = np.empty(len(origins), np.float32)
        for s in range(0, len(origins), BLOCK):
            m = min(BLOCK, len(origins) - s)
            self._rays[:m, :3], self._rays[:m, 3:6] = origins[s : s + m], directions[s : s + m]
            bounds = np.linspace(0, m, min(self.workers, m) + 1).astype(int)
            list(self._pool.map(_cast, [(self._shm.name, a, b) for a, b in zip(bounds[:-1], bounds[1:])]))
            t[s : s + m] = self._rays[:m, 6]
        return t

    def close(self) -> None:
        self._pool.shutdown(cancel_futures=True)
        del self._rays
        self._shm.close()
        self._shm.unlink()
