"""An N^3 grid of signed distance over the padded box, read by trilinear interpolation.

Built from the GT mesh and its oracle (no training samples): `build` = "levelset"
(exact narrow band + fast sweeping, ddfbench.truth.levelset), "exact" (oracle signed
distance at every node) or "auto" (exact up to `exact_max_resolution`, level set
above). Stored as float32 or float16 in an uncompressed `.npz` (arrays `sdf` and a
JSON `header`), loaded with allow_pickle=False. Outside the box the field is the
value at the nearest box point plus the distance to the box. Normals: central
differences of the trilinear field (offsets of one grid step, 6 evaluations per hit).
"""

from __future__ import annotations

import json
import os
import time
from typing import Any, Mapping

import numpy as np
import torch
import torch.nn.functional as F

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import BOX_HALF
from ddfbench.core.representation import Budget, FitData, FitStats, Probe
from ddfbench.evaluate.trace import central_difference_normals
from ddfbench.models._sdf_family import SDFFamily
from ddfbench.truth import levelset

_DTYPES = {"float32": np.float32, "float16": np.float16}


class GridSDF(SDFFamily):
    """cfg: resolution, build (levelset | exact | auto), exact_max_resolution, band_cells, dtype (float32 | float16)."""

    family = "grid_sdf"
    sample_kind = None

    def __init__(self, cfg: Mapping[str, Any], domain: float = BOX_HALF):
        super().__init__(cfg, domain)
        self.resolution = int(self.cfg["resolution"])
        self.build = str(self.cfg["build"])
        self.dtype = str(self.cfg["dtype"])
        if self.resolution < 4:
            raise InputError(f"model.resolution {self.resolution}: must be at least 4")
        if self.build not in ("levelset", "exact", "auto"):
            raise InputError(f"model.build '{self.build}': unknown (levelset | exact | auto)")
        if self.dtype not in _DTYPES:
            raise InputError(f"model.dtype '{self.dtype}': unknown (float32 | float16)")
        self.grid: np.ndarray | None = None  # (n, n, n) stored dtype
        self._volume: torch.Tensor | None = None  # (1, 1, n, n, n) float32 for grid_sample

    def _set_grid(self, grid: np.ndarray) -> None:
        """Store the grid in its storage dtype; float16 clamps to ±65504 (its range) so no value becomes inf."""
        grid = np.nan_to_num(np.asarray(grid, np.float32), nan=0.0, posinf=np.inf, neginf=-np.inf)
        if _DTYPES[self.dtype] == np.float16:
            grid = np.clip(grid, -65504.0, 65504.0)
        self.grid = np.ascontiguousarray(grid, _DTYPES[self.dtype])
        self._volume = torch.from_numpy(self.grid.astype(np.float32))[None, None].to(self.device)

    def fit(self, data: FitData, budget: Budget, probe: Probe | None = None) -> FitStats:
        start = time.perf_counter()
        n, method = self.resolution, self.build
        if method == "auto":
            method = "exact" if n <= int(self.cfg["exact_max_resolution"]) else "levelset"
        if method == "exact":
            grid, info = levelset.exact_sdf_grid(data.oracle, n, self.domain), {}
        else:
            grid, info = levelset.levelset_sdf_grid(data.oracle, n, self.domain,
                                                    band_cells=float(self.cfg["band_cells"]))
        self._set_grid(grid)
        seconds = time.perf_counter() - start
        return FitStats.built(self, seconds, {"build": method, **info}, probe)

    def field(self, points: torch.Tensor) -> torch.Tensor:
        half = self.domain
        inside = points.clamp(-half, half)
        outside = (points - inside).norm(dim=1)
        g = (inside / half).flip(-1).reshape(1, -1, 1, 1, 3)  # grid_sample wants (z, y, x) for a [i, j, k] volume
        v = F.grid_sample(self._volume, g.to(self._volume.dtype), mode="bilinear", padding_mode="border",
                          align_corners=True)
        return v.reshape(-1) + outside

    def surface_normals(self, points: torch.Tensor):
        """Central differences of the trilinear field at surface points (M,3), one grid step (2 domain /
        (resolution - 1), normalized units) to each side per axis -> (outward unit normals (M,3), valid (M,)
        bool: False where the difference vanishes or is not finite, field_evals = 6 M, backward_passes = 0)."""
        step = 2.0 * self.domain / (self.resolution - 1)
        nrm, valid = central_difference_normals(self.field, points, step)
        return nrm, valid, 6 * int(points.shape[0]), 0

    def n_params(self) -> int:
        return int(self.resolution**3)

    def save(self, path: str) -> str:
        if not path.endswith(".npz"):
            path = f"{path}.npz"
        header = {"family": self.family, "domain": self.domain, "resolution": self.resolution, "dtype": self.dtype,
                  "build": self.build, "trace": dict(self.cfg["trace"])}
        return self._publish(path, f"{path}.tmp{os.getpid()}.npz",
                             lambda tmp: np.savez(tmp, sdf=self.grid, header=np.array(json.dumps(header))))

    @classmethod
    def load(cls, path: str, domain: float | None = None) -> "GridSDF":
        try:
            with np.load(path, allow_pickle=False) as z:
                header, grid = json.loads(str(z["header"])), z["sdf"]
        except (OSError, ValueError, KeyError) as exc:
            raise InputError(f"grid_sdf artifact {path}: unreadable ({exc})") from None
        n = int(header["resolution"])
        if grid.shape != (n, n, n) or str(grid.dtype) != header["dtype"]:
            raise InputError(f"grid_sdf artifact {path}: grid {grid.shape} {grid.dtype} does not match its header")
        cfg = {k: header[k] for k in ("resolution", "dtype", "build", "trace")}
        rep = cls(cfg, cls._artifact_domain(path, header, domain))
        rep._set_grid(grid)
        rep._saved_path = path
        return rep


FAMILY = GridSDF
