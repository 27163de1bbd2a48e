"""The interface every shape family implements, and the plain data it exchanges.

Frames: every array is in the normalized frame of the GT mesh (unit cube
[-0.5, 0.5]^3, field domain the padded box [-domain, domain]^3).
"""

from __future__ import annotations

import abc
import enum
import json
import os
import pickle
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, ClassVar, Mapping

import numpy as np
import trimesh

from ddfbench.core import plugins
from ddfbench.core.atomic import write_atomic_named
from ddfbench.core.errors import InputError
from ddfbench.core.geometry import BOX_HALF

if TYPE_CHECKING:  # for the annotation only: ddfbench.fit.checkpoint imports torch
    from ddfbench.fit.checkpoint import Checkpoint


class RayStatus(enum.IntEnum):
    """Outcome of one ray query."""

    MISS = 0
    HIT = 1
    UNDECIDED = 2  # e.g. sphere tracing hit its step cap: never silently a hit


@dataclass
class Hits:
    """Answer to `intersect` for N rays.

    t:       (N,) float32, distance along the unit direction to the first hit; inf where no hit.
    hit:     (N,) bool.
    normal:  (N, 3) float32 unit normals facing the ray (n·d < 0); zeros where no hit or not asked.
    status:  (N,) int8 of RayStatus.
    normal_valid: (N,) bool, False where a normal could not be computed (e.g. zero gradient).
    stats:   work done answering, for the counting layer: field_evals, backward_passes, trace_steps.
    """

    t: np.ndarray
    hit: np.ndarray
    normal: np.ndarray
    status: np.ndarray
    normal_valid: np.ndarray | None = None
    stats: dict[str, int] = field(default_factory=dict)

    @staticmethod
    def empty(n: int) -> "Hits":
        return Hits(
            t=np.full(n, np.inf, np.float32),
            hit=np.zeros(n, bool),
            normal=np.zeros((n, 3), np.float32),
            status=np.full(n, RayStatus.MISS, np.int8),
            normal_valid=np.zeros(n, bool),
        )


@dataclass
class Budget:
    """How much a fit may spend. max_seconds is wall clock of training only (probes excluded)."""

    max_steps: int = 1000
    max_seconds: float = 60.0
    device: str = "cpu"
    seed: int = 0
    n_probes: int = 6  # log-spaced accuracy probes along the budget
    checkpoint: Checkpoint | None = None  # where the fit saves itself and resumes from (ddfbench.fit.checkpoint)


@dataclass
class FitStats:
    """What a fit did: steps taken, training seconds, loss curve and accuracy probes.

    loss_curve: list of (step, seconds, loss).
    probes:     list of dicts {step, seconds, chamfer_l2, fscore_0.01, ...} at log-spaced points.
    status:     "ok" or "failed" (e.g. NaN guard), with message.
    """

    steps: int = 0
    seconds: float = 0.0
    loss_curve: list[tuple[int, float, float]] = field(default_factory=list)
    probes: list[dict[str, float]] = field(default_factory=list)
    status: str = "ok"
    message: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def built(cls, rep: "Representation", seconds: float, extra: dict[str, Any], probe: "Probe | None") -> "FitStats":
        """The stats of a family built in one step rather than trained (grid, mesh): step 1 took `seconds`,
        with one probe of `rep` there when a probe is given."""
        stats = cls(steps=1, seconds=seconds, extra=extra)
        if probe is not None:
            stats.probes.append({"step": 1, "seconds": seconds, **probe(rep)})
        return stats


# A probe maps a representation to cheap accuracy numbers; fit calls it at log-spaced points.
Probe = Callable[["Representation"], dict[str, float]]


class Representation(abc.ABC):
    """A shape family. Subclass in `ddfbench/models/<family>.py` (or a package `models/<family>/`) and expose it as
    `FAMILY`.

    cfg is the `model` config node as a plain dict, checked and completed by `configure` (the family's
    conf/model/<family>.yaml is the one source of its defaults); domain is the half-side of the field box.
    `sample_kind` says what training samples fit wants: "rays" (x, d, t, hit), "sdf" (x, sdf) or None
    (the runner then builds none). `learned` says fit trains something (fit curves, training benches).
    `needs_closed_surface` says its labels rely on a sensible inside/outside (flagged on open meshes).
    """

    family: ClassVar[str] = "abstract"
    sample_kind: ClassVar[str | None] = None
    learned: ClassVar[bool] = False
    # True where training signs come from the inside test: an open input is then flagged in the record.
    needs_closed_surface: ClassVar[bool] = False

    def __init__(self, cfg: Mapping[str, Any], domain: float = BOX_HALF):
        self.cfg = self.configure(cfg)
        self.domain = float(domain)
        self._saved_path: str | None = None
        # what the last to_mesh reported (ddfbench.evaluate.extract info: field_evals, capped, empty, ...); {} if nothing
        self.extract_info: dict[str, Any] = {}

    @classmethod
    def configure(cls, cfg: Mapping[str, Any]) -> dict[str, Any]:
        """The family's YAML defaults overlaid by cfg; an unknown key or a mistyped value is a one-line InputError."""
        return plugins.family_config(cls.family, cfg)

    @abc.abstractmethod
    def fit(self, data: "FitData", budget: Budget, probe: Probe | None = None) -> FitStats:
        """Train or build from data; respect budget.max_steps and budget.max_seconds."""

    @abc.abstractmethod
    def intersect(self, origins: np.ndarray, directions: np.ndarray, normals: bool = True) -> Hits:
        """First hit of rays (N,3) origins and (N,3) unit directions. Skip normal work if normals=False."""

    @abc.abstractmethod
    def to_mesh(self, resolution: int) -> trimesh.Trimesh:
        """A triangle mesh of the surface (possibly empty: zero faces), for geometry metrics; a field
        extraction leaves its info in self.extract_info."""

    @abc.abstractmethod
    def save(self, path: str) -> str:
        """Write the artifact a user would ship; return the path written. A family with a lossy storage_dtype
        rounds the live representation to what it stored: the runner saves before it meshes and renders, so
        a record measures what it ships."""

    @classmethod
    @abc.abstractmethod
    def load(cls, path: str, domain: float | None = None) -> "Representation":
        """Read an artifact written by save (models: torch.load(weights_only=True)). domain: the field half-side
        the caller expects, None for whatever the artifact holds. An artifact stores its own domain and loading
        it for another is a one-line InputError (_artifact_domain); only the mesh's .ply stores none and takes
        the caller's."""

    @classmethod
    def _artifact_domain(cls, path: str, header: Mapping[str, Any], expected: float | None) -> float:
        """The field half-side an artifact's header stores; a one-line InputError when it stores none or the
        caller expects another (expected None: any)."""
        if not isinstance(header.get("domain"), (int, float)):
            raise InputError(f"{cls.family} artifact {path}: its header stores no domain")
        stored = float(header["domain"])
        if expected is not None and float(expected) != stored:
            raise InputError(f"{cls.family} artifact {path}: saved with domain {stored}, loaded with domain {expected}")
        return stored

    def _publish(self, path: str, tmp: str, write: Callable[[str], None]) -> str:
        """Save by file name: write(tmp) fills the temporary file tmp, which is synced and renamed onto path
        (write_atomic_named); remember path and return it."""
        self._saved_path = write_atomic_named(path, tmp, write)
        return path

    def _save_network(self, path: str, state: Mapping[str, Any]) -> str:
        """Save a network family: `<path>.pt` (".pt" added when missing) holding the state dict (name ->
        tensor) and a JSON header {family, domain, cfg}, written to a temporary file and published."""
        import torch

        if not path.endswith(".pt"):
            path = f"{path}.pt"
        header = {"family": self.family, "domain": self.domain, "cfg": self.cfg}
        blob = {"header": json.dumps(header), "state_dict": dict(state)}
        return self._publish(path, f"{path}.tmp{os.getpid()}", lambda tmp: torch.save(blob, tmp))

    @classmethod
    def _read_network(cls, path: str) -> tuple[dict[str, Any], dict[str, Any]]:
        """(header, state dict) of a file written by _save_network (torch.load with weights_only); a
        one-line InputError when it cannot be read or holds another family."""
        import torch

        try:
            blob = torch.load(path, map_location="cpu", weights_only=True)
            header, state = json.loads(blob["header"]), blob["state_dict"]
        except (OSError, RuntimeError, KeyError, ValueError, TypeError, pickle.UnpicklingError) as exc:
            raise InputError(f"{cls.family} artifact {path}: unreadable ({(str(exc) or type(exc).__name__).splitlines()[0]})") from None
        if header.get("family") != cls.family:
            raise InputError(f"{cls.family} artifact {path}: holds family {header.get('family')!r}, not {cls.family}")
        return header, state

    def to(self, device: str) -> "Representation":
        """Move what this representation computes with (its torch modules and tensors) to `device`
        ("cpu" | "cuda[:k]") and answer there from now on; returns self."""
        import torch

        for name, value in list(vars(self).items()):
            if isinstance(value, torch.nn.Module):
                value.to(device)
            elif isinstance(value, torch.Tensor):
                setattr(self, name, value.to(device))
        self.device = device
        return self

    def n_params(self) -> int:
        """Number of stored scalars (network parameters, grid cells, vertex coordinates...)."""
        return 0

    def storage_bytes(self) -> int:
        """File bytes of the saved artifact (the last `save`)."""
        if self._saved_path is None:
            raise RuntimeError(f"{self.family}: storage_bytes() needs save() first")
        p = self._saved_path
        if os.path.isdir(p):
            return sum(os.path.getsize(os.path.join(r, f)) for r, _, fs in os.walk(p) for f in fs)
        return os.path.getsize(p)


@dataclass
class FitData:
    """Everything fit may use: training samples (or None), the normalized GT mesh and its oracle."""

    samples: Any  # ddfbench.sampling.samples.Samples | None
    mesh: trimesh.Trimesh
    oracle: Any  # ddfbench.truth.oracle.Oracle
