"""Device-resident DDF depth: rays in, first-hit t out, torch tensors on the network's device throughout.

`DDF.intersect` takes numpy rays and answers on the host (box entry, compaction of the rays meeting
the box, one `.cpu()` per eval batch). This path is what a GPU renderer wants: the box entry, the
network and the hit rule run on the device in fixed-size chunks with no compaction and no host round
trip (a ray that misses the box is evaluated anyway and masked out), so a chunk is one static-shape
graph that `torch.compile` (or CUDA graphs) can take whole. Precision: fp32, or bf16 / fp16 autocast
(the answer is float32 either way). Depth only (no normals: those need a backward pass).
"""

from __future__ import annotations

from typing import Callable

import torch

from ddfbench.core.geometry import box_entry
from ddfbench.models.ddf import DDF

PRECISIONS = {"fp32": None, "bf16": torch.bfloat16, "fp16": torch.float16}


class DDFDepth:
    """Callable (origins (N,3), unit directions (N,3)) float32 tensors on rep's device -> t (N,) float32, inf on a miss.

    rep: a fitted DDF; precision: fp32 | bf16 | fp16 (autocast); compiled: torch.compile the per-chunk
    function (mode "default"; dynamic shapes, so the last, shorter chunk does not recompile);
    fused (bf16 only, ddfbench.models.ddf.fused): "mlp": the MLP as one Triton kernel, the box entry and encoding
    before it and the hit rule after it in torch (compiled with compiled); "depth": the whole answer as one
    kernel (compiled does not apply);
    chunk: rays per network call (bounds the activations: ~chunk * width * 4 bytes per layer).
    The hit rule is DDF.intersect's: visible, not nearer than min_hit_distance, not beyond the box exit.
    """

    def __init__(self, rep: DDF, precision: str = "fp32", compiled: bool = False, chunk: int = 1 << 20,
                 fused: str | None = None):
        if precision not in PRECISIONS:
            raise ValueError(f"DDF precision '{precision}': unknown ({' | '.join(PRECISIONS)})")
        if fused not in (None, "mlp", "depth"):
            raise ValueError(f"DDF fused '{fused}': unknown (mlp | depth)")
        if fused and precision != "bf16":
            raise ValueError(f"DDF precision '{precision}': the fused kernels compute in bf16 only")
        self.rep, self.precision, self.chunk = rep, precision, int(chunk)
        self.device = next(rep.net.parameters()).device
        rep.net.eval()
        step: Callable[[torch.Tensor, torch.Tensor], torch.Tensor] = self._chunk_depth
        if fused == "depth":
            from ddfbench.models.ddf.fused import FusedDepth

            step = FusedDepth(rep)
        elif fused == "mlp":
            from ddfbench.models.ddf.fused import FusedMLP

            self.mlp = FusedMLP(rep.net)  # the fused path's three parts (ddfbench.bench.fused_parts times each)
            self.encode, self.finish = self._fused_inputs, self._answer
            if compiled:
                self.encode, self.finish = torch.compile(self.encode, dynamic=True), torch.compile(self.finish, dynamic=True)
            step = self._fused_depth
        elif compiled:
            step = torch.compile(step, dynamic=True)
        self._step = step

    def _chunk_depth(self, o: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
        t_entry, t_exit, meets = box_entry(o, d, self.rep.domain)
        dtype = PRECISIONS[self.precision]
        with torch.autocast(self.device.type, dtype=dtype or torch.float32, enabled=dtype is not None):
            dist, logit = self.rep.net(o + t_entry[:, None] * d, d)
        return self._hit(dist, logit, t_entry, t_exit, meets)

    def _fused_inputs(self, o: torch.Tensor, d: torch.Tensor):
        """The fused kernel's input (N, K0) bf16, and the ray coordinate and box entry the answer needs."""
        t_entry, t_exit, meets = box_entry(o, d, self.rep.domain)
        feats, s0 = self.rep.net.features(o + t_entry[:, None] * d, d)
        return self.mlp.pad(feats), s0, t_entry, t_exit, meets

    def _fused_depth(self, o: torch.Tensor, d: torch.Tensor) -> torch.Tensor:
        x, s0, t_entry, t_exit, meets = self.encode(o, d)
        return self.finish(self.mlp(x), s0, t_entry, t_exit, meets)

    def _answer(self, y: torch.Tensor, s0, t_entry, t_exit, meets) -> torch.Tensor:
        dist, logit = self.rep.net.outputs(y, s0)
        return self._hit(dist, logit, t_entry, t_exit, meets)

    def _hit(self, dist, logit, t_entry, t_exit, meets) -> torch.Tensor:
        """t (N,) where the ray hits, else inf: distance dist (N,) from the box entry t_entry (N,)."""
        dist = dist.float().clamp_min(0.0)
        visible = self.rep._hit_from(dist, None if logit is None else logit.float())
        hit = visible & meets & self.rep._accept(t_entry, t_exit, dist)
        return torch.where(hit, t_entry + dist, torch.inf)

    @torch.no_grad()
    def __call__(self, origins: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
        return torch.cat([self._step(origins[s : s + self.chunk], directions[s : s + self.chunk])
                          for s in range(0, len(origins), self.chunk)] or [origins.new_zeros(0)])
