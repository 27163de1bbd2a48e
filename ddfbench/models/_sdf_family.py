"""Shared bases of the SDF-like families: rays by sphere tracing (ddfbench.evaluate.trace), mesh by marching cubes.

SDFFamily: a subclass provides `field(points (M, 3) torch float32 on self.device) -> (M,)`
signed distance and `surface_normals`; sdf on numpy points, intersect and to_mesh are here.
NetSDFFamily: a field that is one torch module `self.net` (normals by autograd; artifact =
one torch file {"header": JSON config, "state_dict"}, read with weights_only=True).
The model config's optional `trace` mapping sets TraceOptions.
"""

from __future__ import annotations

import abc
from typing import Any, Callable, Mapping

import numpy as np
import torch
import trimesh

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import BOX_HALF
from ddfbench.core.representation import Budget, FitData, FitStats, Hits, Probe, Representation
from ddfbench.evaluate import extract
from ddfbench.evaluate.trace import TraceOptions, autograd_normals, sphere_trace, to_hits
from ddfbench.fit.train import Schedule, train_loop

FIELD_BATCH = 65536  # points per field call when evaluating numpy arrays


class SDFFamily(Representation):
    """Representation answering rays by sphere tracing its signed-distance field."""

    needs_closed_surface = True  # signs come from the inside test

    def __init__(self, cfg: Mapping[str, Any], domain: float = BOX_HALF):
        super().__init__(cfg, domain)
        self.trace_options = TraceOptions.from_cfg(self.cfg)
        self.device = "cpu"

    @abc.abstractmethod
    def field(self, points: torch.Tensor) -> torch.Tensor:
        """Signed distance (M,) at points (M, 3) float32 on self.device (negative inside)."""

    @abc.abstractmethod
    def surface_normals(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, int, int]:
        """Outward unit normals at surface points (M, 3) -> (normals (M, 3), valid (M,), field_evals, backward_passes)."""

    def sdf(self, points: np.ndarray) -> np.ndarray:
        """Signed distance (N,) float32 at numpy points (N, 3), in batches."""
        p = np.asarray(points, np.float32).reshape(-1, 3)
        with torch.no_grad():
            return extract.evaluate(lambda chunk: self.field(torch.from_numpy(chunk).to(self.device)), p, FIELD_BATCH)

    def _batched_field(self, points: torch.Tensor) -> torch.Tensor:
        return torch.cat([self.field(points[s : s + FIELD_BATCH]).reshape(-1) for s in range(0, len(points), FIELD_BATCH)]) \
            if len(points) else points.new_zeros(0)

    def intersect(self, origins: np.ndarray, directions: np.ndarray, normals: bool = True) -> Hits:
        result = sphere_trace(self._batched_field, origins, directions, self.domain, self.trace_options, self.device)
        if not normals or not result.hit.any():
            return to_hits(result, directions)
        o = np.asarray(origins, np.float32).reshape(-1, 3)[result.hit]
        d = np.asarray(directions, np.float32).reshape(-1, 3)[result.hit]
        points = torch.from_numpy(o + result.t[result.hit, None] * d).to(self.device)
        nrm, valid, evals, backward = self.surface_normals(points)
        return to_hits(result, directions, nrm.detach().cpu().numpy(), valid.cpu().numpy(), evals, backward)

    def to_mesh(self, resolution: int, level: float = 0.0) -> trimesh.Trimesh:
        """Marching cubes of the field's `level` set (unit-cube units; 0: the surface) on a resolution^3 grid over
        the domain box (empty mesh flagged in extract_info).

        cfg.extract_coarse > 1 evaluates coarse to fine, only near the surface, assuming the field's slope
        is at most cfg.extract_lipschitz there (extract.banded_grid); 1 evaluates every node.
        """
        field = self.sdf if level == 0 else (lambda p: self.sdf(p) - np.float32(level))
        mesh, self.extract_info = extract.sdf_to_mesh(
            field, int(resolution), self.domain, coarse=int(self.cfg["extract_coarse"]),
            lipschitz=float(self.cfg["extract_lipschitz"]))
        return mesh


class NetSDFFamily(SDFFamily):
    """An SDF family whose field is the torch module `self.net` (built by the subclass's __init__ from cfg)."""

    net: torch.nn.Module
    learned = True

    def field(self, points: torch.Tensor) -> torch.Tensor:
        return self.net(points)

    def surface_normals(self, points: torch.Tensor):
        """Autograd normals: one batched backward pass; counts one evaluation and one backward per point."""
        nrm, valid = autograd_normals(self.net, points)
        m = int(points.shape[0])
        return nrm, valid, m, m

    def n_params(self) -> int:
        return int(sum(p.numel() for p in self.net.parameters()))

    def _sdf_tensors(self, data: FitData) -> tuple[torch.Tensor, torch.Tensor]:
        """The SDF samples on self.device: points x (N, 3) and signed distances (N,), float32 unit-cube
        units; an InputError naming the family where the sampler gave none."""
        samples = data.samples
        if samples is None or samples.sdf is None:
            raise InputError(f"{self.family}: fit needs SDF samples (x, sdf); the sampler gave none")
        return (torch.from_numpy(np.asarray(samples.x, np.float32)).to(self.device),
                torch.from_numpy(np.asarray(samples.sdf, np.float32)).to(self.device))

    def _train(self, module: torch.nn.Module, optimizer: torch.optim.Optimizer, step_fn: Callable[[int], torch.Tensor], budget: Budget,
               probe: Probe | None, **kw: Any) -> FitStats:
        """train.train_loop under the preset's lr schedule (cfg) and grad_clip, probe(self) at the budget's
        probes; kw goes to train_loop (state: other objects its checkpoint keeps)."""
        grad_clip = self.cfg["grad_clip"]
        return train_loop(module, optimizer, step_fn, budget, Schedule.from_cfg(self.cfg),
                          (lambda: probe(self)) if probe is not None else None,
                          grad_clip=float(grad_clip) if grad_clip else None, desc=self.family, **kw)

    def save(self, path: str) -> str:
        return self._save_network(path, {k: v.detach().cpu() for k, v in self.net.state_dict().items()})

    @classmethod
    def load(cls, path: str, domain: float | None = None) -> "NetSDFFamily":
        header, state = cls._read_network(path)
        stored_domain = cls._artifact_domain(path, header, domain)
        try:
            rep = cls(header["cfg"], stored_domain)
            rep.net.load_state_dict(state)
        except (RuntimeError, KeyError, ValueError, TypeError) as exc:
            raise InputError(f"{cls.family} artifact {path}: unreadable ({str(exc).splitlines()[0]})") from None
        rep.net.eval()
        rep._saved_path = path
        return rep
