"""What every section is given: the options, this section's sizes, and cached shapes and oracles."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from omegaconf import OmegaConf

from ddfbench.bench.results import SectionResult
from ddfbench.core import plugins
from ddfbench.core.geometry import BOX_HALF
from ddfbench.core.representation import Budget, FitData, Representation
from ddfbench.sampling.samples import Samples
from ddfbench.truth.oracle import Oracle
from ddfbench.truth.shapes import Shape, load_shape

DOMAIN = BOX_HALF  # conf/config.yaml `domain`: half-side of the field box


def preset(group: str, name: str, **overrides: Any) -> dict[str, Any]:
    """conf/<group>/<name>.yaml's config as a plain dict (${domain} resolved), with overrides applied."""
    root = OmegaConf.create({"domain": DOMAIN, "node": plugins.defaults(group, name)})
    return {**OmegaConf.to_container(root, resolve=True)["node"], **overrides}


def model_preset(name: str, **overrides: Any) -> dict[str, Any]:
    """conf/model/<name>.yaml (a family, or a preset naming its family) with overrides."""
    return preset("model", name, **overrides)


@dataclass
class Context:
    """device: "cpu" | "cuda[:k]"; sizes: this section's size parameters; repeats, warmup: timed and
    untimed warm calls; workdir: scratch space for runs the section starts; oracle_backend: the ground
    truth's backend ("open3d", or "warp" where open3d is not installed); partial: the result a long
    section fills as it goes, kept when it fails or is stopped midway (bench.__main__.run_section)."""

    device: str
    sizes: dict[str, Any]
    repeats: int
    warmup: int
    workdir: str
    threads: int
    oracle_backend: str = "open3d"
    partial: SectionResult | None = None
    _shapes: dict[str, Shape] = field(default_factory=dict)
    _oracles: dict[tuple[str, str], Oracle] = field(default_factory=dict)

    def shape(self, name: str) -> Shape:
        if name not in self._shapes:
            self._shapes[name] = load_shape({"name": name})
        return self._shapes[name]

    def oracle(self, name: str, backend: str | None = None) -> Oracle:
        """The shape's oracle with `backend` (default: oracle_backend), built once."""
        backend = backend or self.oracle_backend
        if (name, backend) not in self._oracles:
            device = self.device if backend == "warp" else "cpu"  # Warp's CPU kernels run on one core
            self._oracles[(name, backend)] = Oracle(self.shape(name).mesh, backend=backend, device=device)
        return self._oracles[(name, backend)]

    @property
    def fit_steps(self) -> int:
        """The sizes' fixed fit steps; 0 when a fit runs for fit_seconds of wall clock instead."""
        return int(self.sizes.get("fit_steps") or 0)

    def timed_fit(self, rep: Representation, samples: Samples) -> dict[str, Any]:
        """rep fit on samples of the sizes' shape on this device, no probes: for the sizes' fit_steps when set
        (fixed work; the lr schedule runs by steps), else for fit_seconds of wall clock.
        Returns {fit_steps, fit_seconds, fit_status, fit_device}."""
        name, steps = self.sizes["shape"], self.fit_steps
        seconds = float("inf") if steps else float(self.sizes["fit_seconds"])
        stats = rep.fit(FitData(samples, self.shape(name).mesh, self.oracle(name)),
                        Budget(max_steps=steps or 10**9, max_seconds=seconds, device=self.device, n_probes=0))
        return {"fit_steps": stats.steps, "fit_seconds": stats.seconds, "fit_status": stats.status,
                "fit_device": self.device}

    def fit_spec(self) -> dict[str, Any]:
        """What a fit of this section is made by (bench.prepared names saved networks by it): shape and budget."""
        steps = self.fit_steps
        return {"shape": self.sizes["shape"], **({"steps": steps} if steps else {"seconds": self.sizes["fit_seconds"]})}
