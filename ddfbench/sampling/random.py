"""Random sampling (the DDF paper's baseline): points uniform in the field box.

Rays: unit directions uniform on the sphere, label = the oracle's first hit (inf for a miss).
Points inside the shape are kept (their rays hit the shape from within).
SDF: the oracle's signed distance at the points. n_samples labels, 29 bytes each for rays
(16 for SDF): 1e7 rays is 0.3 GB. Work is streamed in chunks of 2M.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from ddfbench.sampling import params
from ddfbench.sampling.box import uniform_in_box
from ddfbench.sampling.collect import Collector, chunks
from ddfbench.sampling.directions import uniform_directions
from ddfbench.sampling.samples import Samples
from ddfbench.truth.oracle import Oracle
from ddfbench.truth.shapes import Shape

KEYS = ("n_samples", "box", "max_samples")
CHUNK = 1 << 21


def sample(shape: Shape, oracle: Oracle, cfg: Mapping[str, Any], kind: str,
           rng: np.random.Generator) -> tuple[Samples, dict[str, Any], dict[str, int]]:
    """n_samples labels of `kind` ("rays" | "sdf"), the parameters used, and (no) rejections."""
    params.check_keys(cfg, KEYS)
    p = {"n_samples": params.count(cfg, "n_samples"), "box": params.positive(cfg, "box"),
         "max_samples": params.count(cfg, "max_samples")}
    out = Collector(p["max_samples"], f"random sampling of {shape.name}")
    out.expect(p["n_samples"], kind)
    for sl in chunks(p["n_samples"], CHUNK):
        x = uniform_in_box(rng, sl.stop - sl.start, p["box"])
        if kind == "sdf":
            out.add(x, sdf=oracle.signed_distance(x))
        else:
            d = uniform_directions(rng, len(x))
            out.add(x, d, oracle.hit_distance(x, d))
    return out.samples(), p, {}
