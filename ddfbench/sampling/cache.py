"""Where a dataset lives on disk: a hash of everything that determines its labels."""

from __future__ import annotations

import hashlib
import json
import os
import re
from typing import Any, Mapping

import numpy as np

from ddfbench.truth.oracle import Oracle
from ddfbench.truth.shapes import Shape

# bump when a sampler's output changes for the same config; 2: ray samples carry line_hit; 3: surface labels exact
# for the stored float32 rays
CACHE_VERSION = 3


def dataset_key(shape: Shape, oracle: Oracle, cfg: Mapping[str, Any], kind: str, seed: int) -> str:
    """16 hex digits of sha256 over the shape (name, transform, vertex and face bytes), the sampling
    config, kind, seed, the oracle's inside-test votes, its ray caster where that is not open3d (backends differ in a
    few rejections at edges, so each has its own draw; open3d's keys are those from before the field) and
    CACHE_VERSION."""
    h = hashlib.sha256()
    head = {"shape": shape.name, "transform": shape.transform, "sampling": dict(cfg), "kind": kind, "seed": int(seed),
            "occupancy_rays": oracle.occupancy_rays, "version": CACHE_VERSION}
    if oracle.backend != "open3d":
        head["backend"] = oracle.backend
    h.update(json.dumps(head, sort_keys=True, default=str).encode())
    h.update(np.ascontiguousarray(shape.mesh.vertices, np.float64).tobytes())
    h.update(np.ascontiguousarray(shape.mesh.faces, np.int64).tobytes())
    return h.hexdigest()[:16]


def dataset_path(cache_dir: str, shape: Shape, strategy: str, kind: str, key: str) -> str:
    """cache_dir/<shape>-<strategy>-<kind>-<key>.npz (shape name reduced to safe characters)."""
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", shape.name) or "shape"
    return os.path.join(cache_dir, f"{name}-{strategy}-{kind}-{key}.npz")
