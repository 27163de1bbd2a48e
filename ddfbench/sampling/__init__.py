"""Training data: labelled samples from a strategy (random | pov | surface), cached on disk.

A strategy is a module here with `sample(shape, oracle, cfg, kind, rng) -> (Samples, params,
rejected)` and a config conf/sampling/<name>.yaml; nothing else needs to change to add one.
"""

from __future__ import annotations

import importlib
import logging
import os
import pkgutil
import time
import zipfile
from typing import Any, Mapping

import numpy as np

from ddfbench.core.errors import InputError, one_line
from ddfbench.sampling.cache import dataset_key, dataset_path
from ddfbench.sampling.samples import Samples
from ddfbench.truth.oracle import Oracle
from ddfbench.truth.shapes import Shape

KINDS = ("rays", "sdf")
log = logging.getLogger(__name__)


def available_strategies() -> list[str]:
    """Names of the modules in this package that define `sample`."""
    names = [m.name for m in pkgutil.iter_modules(__path__) if not m.ispkg and not m.name.startswith("_")]
    return sorted(n for n in names if hasattr(importlib.import_module(f"{__name__}.{n}"), "sample"))


def _strategy(name: Any):
    if not isinstance(name, str) or name not in available_strategies():
        raise InputError(f"sampling.strategy={name!r}: unknown strategy (available: {', '.join(available_strategies())})")
    return importlib.import_module(f"{__name__}.{name}")


def line_hits(oracle: Oracle, x: np.ndarray, d: np.ndarray, hit: np.ndarray) -> np.ndarray:
    """(N,) bool: the line through x (N,3) along unit d (N,3) meets the surface, given hit (N,) of the ray
    from x along d: a hit, or a miss whose backward ray from x along -d meets the surface (one cast per miss).
    The same label for every strategy, so that a family reading it gets the same information from each."""
    out = np.asarray(hit, bool).copy()
    miss = np.flatnonzero(~out)
    out[miss] = oracle.any_hit(x[miss], -np.asarray(d[miss]))
    return out


def build(shape: Shape, oracle: Oracle, cfg: Mapping[str, Any], kind: str, seed: int,
          cache_dir: str) -> tuple[Samples, str, dict[str, Any]]:
    """Labelled samples for `shape`, the path of their cached .npz, and the info for the run record.

    cfg: the sampling config (key `strategy` picks the module); kind: "rays" (x, d, t, hit, line_hit) or
    "sdf" (x, sdf). A dataset already cached under the same key is loaded instead of rebuilt (one that cannot be
    read, cut short by a crash or a full disk, is rebuilt over, with a logged line naming it).
    info: strategy, kind, n_samples, n_hit, sampling_s (of the build, also on a cache hit),
    samples_per_s, cache_hit, load_s, rejected {reason: count}, memory_bytes, the strategy's parameters.
    """
    module = _strategy(cfg.get("strategy"))
    if kind not in KINDS:
        raise InputError(f"sample kind {kind!r}: unknown (rays | sdf)")
    key = dataset_key(shape, oracle, cfg, kind, seed)
    path = dataset_path(cache_dir, shape, cfg["strategy"], kind, key)
    if os.path.exists(path):
        t0 = time.perf_counter()
        try:
            samples = Samples.load_npz(path)
        except (OSError, ValueError, EOFError, KeyError, zipfile.BadZipFile) as exc:  # cut short, garbled
            log.warning("%s: not a readable dataset (%s): built anew", path, one_line(exc))
        else:
            return samples, path, dict(samples.meta, cache_hit=True, load_s=time.perf_counter() - t0)

    t0 = time.perf_counter()
    samples, params, rejected = module.sample(shape, oracle, cfg, kind, np.random.default_rng(seed))
    if kind == "rays":
        samples.line_hit = line_hits(oracle, samples.x, samples.d, samples.hit)
    seconds = time.perf_counter() - t0
    if len(samples) == 0:
        raise InputError(
            f"shape {shape.name}: sampling={cfg['strategy']} produced no samples, every candidate was rejected "
            f"({', '.join(f'{k} {v}' for k, v in rejected.items()) or 'none drawn'})"
        )
    arrays = [a for a in (samples.x, samples.d, samples.t, samples.hit, samples.line_hit, samples.sdf) if a is not None]
    samples.meta = {
        "strategy": cfg["strategy"], "kind": kind, "seed": int(seed), "n_samples": len(samples),
        "n_hit": int(samples.hit.sum()) if samples.hit is not None else None,
        "n_line_miss": int((~samples.line_hit).sum()) if samples.line_hit is not None else None,
        "sampling_s": seconds, "samples_per_s": len(samples) / max(seconds, 1e-9),
        "rejected": rejected, "memory_bytes": int(sum(a.nbytes for a in arrays)), **params,
    }
    os.makedirs(cache_dir, exist_ok=True)
    samples.save_npz(path)
    return samples, path, dict(samples.meta, cache_hit=False, load_s=0.0)
