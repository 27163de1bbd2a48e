"""SDF samples labelled by the oracle around the surface: the training data of a neural SDF where a
benchmark or a test needs one without a sampling config (the tracer benchmark, the SDF-family tests).

Not a strategy of the sampling experiment (it has no `sample` and no conf/sampling YAML): a fixed
mixture, 45% surface + N(0, 0.005), 45% surface + N(0, 0.03), 10% uniform in the field box.
"""

from __future__ import annotations

import numpy as np

from ddfbench.core.geometry import BOX_HALF
from ddfbench.sampling.box import uniform_in_box
from ddfbench.sampling.samples import Samples
from ddfbench.truth.oracle import Oracle


def oracle_sdf_samples(mesh, oracle: Oracle, n: int, seed: int, domain: float = BOX_HALF) -> Samples:
    """n SDF samples labelled by the oracle: 45% surface + N(0, 0.005), 45% surface + N(0, 0.03), 10% uniform in the box."""
    rng = np.random.default_rng(seed)
    n_near = int(0.45 * n)
    surface = np.asarray(mesh.sample(2 * n_near, seed=int(rng.integers(2**31))), np.float32)
    sigma = np.r_[np.full(n_near, 0.005), np.full(n_near, 0.03)].astype(np.float32)[:, None]
    near = surface + rng.normal(size=surface.shape).astype(np.float32) * sigma
    uniform = uniform_in_box(rng, n - 2 * n_near, domain)
    x = np.clip(np.concatenate([near, uniform]), -domain, domain)
    return Samples(x=x, sdf=oracle.signed_distance(x), meta={"strategy": "oracle_sdf", "seed": seed})
