"""Sphere tracing, shared by every SDF-like family.

A field is a torch callable `field(points (M, 3) float32) -> (M,)` signed distance
(negative inside) on the tracer's device; `numpy_field` wraps a numpy one. All
tracing state lives in torch tensors on that device.

Per ray (N rays, unit directions):

1. Clip to the domain box [-domain, domain]^3 (slab test): a ray that misses the
   box is a MISS with no field evaluation; the others march over
   [t_enter, min(t_exit, t_max)].
2. March with active-set compaction: each step evaluates the field only at the
   rays still marching. A ray traces toward the zero level from the side it
   starts on (a camera inside the object finds the exit).
3. Hit test: |f| < tol = eps * t + eps_abs. A converged ray takes one last free
   step t + r (r the side-signed distance; never past the surface of a 1-Lipschitz field).
4. Over-relaxation (Keinert et al. 2014, "Enhanced sphere tracing"): with
   omega > 1 the step is omega * r. When the unbounding spheres at the last two
   points do not overlap (r_prev + r < step), the segment between them may hold
   a surface: the ray steps back to the plain step t_prev + r_prev and marches
   with omega = 1 from there on. For a 1-Lipschitz field this never passes a
   surface that plain tracing finds.
5. Sign change: a plain step that lands on the far side (r <= -tol, possible for
   fields that are not 1-Lipschitz) brackets a root in [t_prev, t]; it is a HIT,
   refined by `refine_steps` Illinois regula-falsi iterations.
6. Step cap: a ray still marching after `max_steps` steps is UNDECIDED (t = inf,
   hit = False), counted in stats, never silently a hit.

Start offset rule (secondary rays): a ray whose first evaluated point lies within
`start_offset` of the surface (|f| < start_offset, e.g. a shadow ray leaving a hit
point) first *escapes*: it advances in fixed steps of `start_offset` until
|f| >= start_offset, and only then starts tracing from the side it reached
(outside for a ray leaving the surface, inside for one entering it). It cannot
report the surface it starts on. A ray that has not escaped after
`escape_steps` steps grazes its surface (|cos| below about 1/escape_steps) and is
UNDECIDED.

Counts: trace_steps = field evaluations inside the march (one per active ray per
step); field_evals = trace_steps + refinement evaluations.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import torch

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import box_entry
from ddfbench.core.representation import Hits, RayStatus

TorchField = Callable[[torch.Tensor], torch.Tensor]


def numpy_field(fn: Callable[[np.ndarray], np.ndarray]) -> TorchField:
    """Wrap a numpy field (M, 3) float32 -> (M,) as a torch field (CPU tensors)."""

    def field(points: torch.Tensor) -> torch.Tensor:
        values = np.asarray(fn(points.detach().cpu().numpy()), np.float32).reshape(-1)
        return torch.from_numpy(values).to(points.device)

    return field


@dataclass
class TraceOptions:
    """Sphere-tracing settings (see the module docstring). Lengths in normalized units."""

    eps: float = 1e-5  # relative hit tolerance: |f| < eps * t + eps_abs
    eps_abs: float = 1e-6
    max_steps: int = 256
    omega: float = 1.0  # over-relaxation factor in (0, 2); 1 = plain sphere tracing
    refine_steps: int = 24  # at most this many Illinois iterations on a bracketed sign change
    start_offset: float = 5e-4  # |f(origin)| below this: the ray starts on a surface and escapes first
    escape_steps: int = 16
    t_max: float = float("inf")  # far bound beyond the box clip

    @staticmethod
    def from_cfg(cfg: dict) -> "TraceOptions":
        """From a model config's `trace` mapping, which names every field above (the family's YAML declares them
        all, so a run never takes a default of this class)."""
        sub = dict(cfg["trace"])
        fields = set(TraceOptions.__dataclass_fields__)
        unknown, missing = set(sub) - fields, fields - set(sub)
        if unknown:
            raise InputError(f"model.trace keys {sorted(unknown)}: unknown (known: {sorted(fields)})")
        if missing:
            raise InputError(f"model.trace.{sorted(missing)[0]}: missing (the family's YAML declares every trace key)")
        opts = TraceOptions(**{k: type(getattr(TraceOptions, k))(v) for k, v in sub.items()})
        opts.check()
        return opts

    def check(self) -> None:
        if not 0.0 < self.omega < 2.0:
            raise InputError(f"trace.omega {self.omega}: must be in (0, 2)")
        if self.max_steps < 1 or self.escape_steps < 1 or self.refine_steps < 0:
            raise InputError(f"trace steps max={self.max_steps} escape={self.escape_steps} refine={self.refine_steps}: "
                             "max and escape must be >= 1, refine >= 0")
        if self.eps < 0 or self.eps_abs <= 0 or self.start_offset <= 0:
            raise InputError(f"trace eps={self.eps} eps_abs={self.eps_abs} start_offset={self.start_offset}: "
                             "eps >= 0, eps_abs > 0 and start_offset > 0 needed")


@dataclass
class TraceResult:
    """t (N,) float32 (inf unless hit), hit (N,) bool, status (N,) int8 RayStatus; work counts;
    host_syncs: device-to-host round trips of the loop (active-set compaction, the bracket and escape
    checks; the Illinois refinement and the final copy not counted): on CUDA each waits for the device."""

    t: np.ndarray
    hit: np.ndarray
    status: np.ndarray
    field_evals: int
    trace_steps: int
    host_syncs: int = 0


def sphere_trace(field: TorchField, origins: np.ndarray, directions: np.ndarray, domain: float,
                 options: TraceOptions | None = None, device: str | torch.device = "cpu") -> TraceResult:
    """Trace N rays, origins (N, 3) and unit directions (N, 3), through `field` clipped to the box
    [-domain, domain]^3 (normalized units; see module docstring) -> TraceResult: t (N,) float32 distance
    along the ray (inf unless hit), hit (N,) bool, status (N,) int8 RayStatus and the work counts."""
    opt = options or TraceOptions()
    opt.check()
    dev = torch.device(device)
    o = torch.as_tensor(np.asarray(origins, np.float32).reshape(-1, 3), device=dev)
    d = torch.as_tensor(np.asarray(directions, np.float32).reshape(-1, 3), device=dev)
    n = o.shape[0]
    t_out = torch.full((n,), float("inf"), device=dev)
    status = torch.full((n,), int(RayStatus.MISS), dtype=torch.int8, device=dev)
    evals, syncs = 0, 1
    with torch.no_grad():
        t_enter, t_exit, _ = box_entry(o, d, domain)
        t_far_all = t_exit.clamp_max(opt.t_max)
        # per active ray: index, t, previous point (t_prev, r_prev), side sign, omega, escape phase.
        # Rows are written back with where-scatters through idx (no sync) and compacted with one
        # nonzero per step (the one round trip compaction needs: the new active count).
        idx = torch.nonzero(t_enter <= t_far_all).squeeze(1)
        t = t_enter[idx]
        t_far = t_far_all[idx]
        t_prev = t.clone()
        r_prev = torch.zeros_like(t)
        side = torch.ones_like(t)
        omega = torch.full_like(t, opt.omega)
        escaping = torch.zeros_like(t, dtype=torch.bool)
        bracket: list[tuple[torch.Tensor, ...]] = []  # (ray idx, t_out, f_out, t_in, f_in, side)

        scaled = opt.omega != 1.0  # steps are omega * r (per ray: omega falls back to 1)
        relax = opt.omega > 1.0  # without over-relaxation no step is ever taken back
        any_escaping = False  # set at step 0; the escape bookkeeping runs only while a ray escapes
        for step in range(opt.max_steps):
            if idx.numel() == 0:
                break
            f = field(o[idx] + t[:, None] * d[idx]).reshape(-1).float()
            evals += idx.numel()
            if step == 0:
                escaping = f.abs() < opt.start_offset
                side = torch.where(f < 0, -1.0, 1.0)
                any_escaping = bool(escaping.any())
                syncs += 1
            done = None  # rays that stop this step (None: none yet)
            free = None  # rays that take a sphere-tracing step (None: all)
            if any_escaping:  # escape phase: leave the surface the ray starts on
                escaped = escaping & (f.abs() >= opt.start_offset)
                side = torch.where(escaped, torch.where(f < 0, -1.0, 1.0), side)
                escaping = escaping & ~escaped
                stuck = escaping & (step >= opt.escape_steps)
                status[idx] = torch.where(stuck, int(RayStatus.UNDECIDED), status[idx])
                done, free = stuck, ~escaping
            r = side * f
            if relax:
                relaxed = (omega > 1.0) & (step > 0)
                if any_escaping:
                    relaxed &= ~escaping & ~escaped
                sor_fail = relaxed & (r_prev + r < t - t_prev)
                free = ~sor_fail if free is None else free & ~sor_fail
            tol = opt.eps * t + opt.eps_abs
            converged = r.abs() < tol
            crossed = r <= -tol
            if free is not None:
                converged &= free
                crossed &= free

            status[idx] = torch.where(converged | crossed, int(RayStatus.HIT), status[idx])
            t_out[idx] = torch.where(converged, t + r, t_out[idx])
            syncs += 1
            if bool(crossed.any()):
                c = torch.nonzero(crossed).squeeze(1)
                syncs += 1
                bracket.append((idx[c], t_prev[c], r_prev[c], t[c], r[c], side[c]))
            done = converged | crossed if done is None else done | converged | crossed

            # next position; a relaxed step past the far bound falls back to the plain step
            if scaled:
                past = t + omega * r > t_far
                omega = torch.where(sor_fail | past if relax else past, torch.ones_like(omega), omega)
                new_t = t + omega * r
            else:
                new_t = t + r
            if any_escaping:
                new_t = torch.where(escaping, t + opt.start_offset, new_t)
            if relax:
                new_t = torch.where(sor_fail, t_prev + r_prev, new_t)
                held = sor_fail | escaping if any_escaping else sor_fail
                t_prev, r_prev = torch.where(held, t_prev, t), torch.where(held, r_prev, r)
            elif any_escaping:
                t_prev, r_prev = torch.where(escaping, t_prev, t), torch.where(escaping, r_prev, r)
            else:
                t_prev, r_prev = t, r
            t = new_t
            keep = torch.nonzero(~(done | (t > t_far))).squeeze(1)  # past the far bound: left the box
            syncs += 1
            idx, t, t_far, t_prev, r_prev, side = idx[keep], t[keep], t_far[keep], t_prev[keep], r_prev[keep], side[keep]
            if scaled:
                omega = omega[keep]
            if any_escaping:
                escaping = escaping[keep]
                any_escaping = bool(escaping.any())
                syncs += 1
        trace_steps = evals
        status[idx] = int(RayStatus.UNDECIDED)

        for ray, a, fa, b, fb, sd in bracket:
            root, k = _illinois(field, o[ray], d[ray], a, fa, b, fb, sd, opt)
            t_out[ray] = root
            evals += k
    hit = status == int(RayStatus.HIT)
    t_out = torch.where(hit, t_out, torch.full_like(t_out, float("inf")))
    return TraceResult(t=t_out.cpu().numpy(), hit=hit.cpu().numpy(), status=status.cpu().numpy(),
                       field_evals=int(evals), trace_steps=int(trace_steps), host_syncs=syncs)


def _illinois(field: TorchField, o: torch.Tensor, d: torch.Tensor, a: torch.Tensor, fa: torch.Tensor,
              b: torch.Tensor, fb: torch.Tensor, side: torch.Tensor, opt: TraceOptions) -> tuple[torch.Tensor, int]:
    """Root of side*f on [a, b] with fa > 0 > fb (Illinois regula falsi, at most opt.refine_steps
    evaluations per ray; a ray stops at a point on its own side within the hit tolerance)
    -> (t (M,), evaluations)."""
    root = false_position(a, fa, b, fb)
    live = torch.arange(a.numel(), device=a.device)
    last = torch.zeros_like(a)  # +1: a moved last, -1: b moved last
    evals = 0
    for _ in range(opt.refine_steps):
        if live.numel() == 0:
            break
        c = (a * fb - b * fa) / (fb - fa)
        c = torch.where(torch.isfinite(c) & (c > a) & (c < b), c, 0.5 * (a + b))
        fc = side[live] * field(o[live] + c[:, None] * d[live]).reshape(-1).float()
        evals += live.numel()
        root[live] = c
        out = fc > 0
        fb = torch.where(out & (last > 0), 0.5 * fb, fb)
        fa = torch.where(~out & (last < 0), 0.5 * fa, fa)
        a, fa = torch.where(out, c, a), torch.where(out, fc, fa)
        b, fb = torch.where(out, b, c), torch.where(out, fb, fc)
        last = torch.where(out, 1.0, -1.0)
        keep = ~out | (fc >= opt.eps * c + opt.eps_abs)  # converged from the ray's side only
        live, a, fa, b, fb, last = live[keep], a[keep], fa[keep], b[keep], fb[keep], last[keep]
    if live.numel():
        root[live] = false_position(a, fa, b, fb)
    return root, evals


def false_position(a: torch.Tensor, fa: torch.Tensor, b: torch.Tensor, fb: torch.Tensor) -> torch.Tensor:
    """The regula-falsi estimate (a fb - b fa) / (fb - fa) of a root bracketed by [a, b] (fa > 0 > fb), or the
    bracket's midpoint where that is not finite: a field that jumps to -inf past its surface (a diverged network)
    gives inf / inf, and a hit must never report t = NaN."""
    c = (a * fb - b * fa) / (fb - fa)
    return torch.where(torch.isfinite(c), c, 0.5 * (a + b))


# ---- normals ------------------------------------------------------------------------------
def autograd_normals(field: TorchField, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Unit gradient of the field at points (M, 3) by one batched backward pass -> (normals (M,3), valid (M,))."""
    with torch.enable_grad():
        p = points.detach().requires_grad_(True)
        (grad,) = torch.autograd.grad(field(p).sum(), p)
    return _unit(grad)


def central_difference_normals(field: TorchField, points: torch.Tensor, step: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Unit central-difference gradient (6 evaluations per point, spacing 2*step) -> (normals, valid)."""
    offsets = torch.eye(3, device=points.device, dtype=points.dtype) * step
    probes = torch.cat([points[:, None, :] + offsets, points[:, None, :] - offsets], dim=1)  # (M, 6, 3)
    with torch.no_grad():
        v = field(probes.reshape(-1, 3)).reshape(-1, 6).float()
    return _unit(v[:, :3] - v[:, 3:])


def _unit(g: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    norm = g.norm(dim=1, keepdim=True)
    valid = (norm.squeeze(1) > 1e-12) & torch.isfinite(norm.squeeze(1))
    return torch.where(valid[:, None], g / norm.clamp_min(1e-12), torch.zeros_like(g)), valid


def to_hits(result: TraceResult, directions: np.ndarray, normals: np.ndarray | None = None,
            normal_valid: np.ndarray | None = None, normal_evals: int = 0, backward_passes: int = 0) -> Hits:
    """Hits from a trace and (optionally) normals of the hit rays (H, 3), turned to face the ray (n·d < 0).

    stats: field_evals (trace + normal evaluations), trace_steps, backward_passes (points differentiated),
    undecided (rays that hit the step cap or grazed their start surface), host_syncs (the trace's
    device-to-host round trips, TraceResult.host_syncs).
    """
    n = len(result.t)
    out = Hits.empty(n)
    out.t, out.hit, out.status = result.t.astype(np.float32), result.hit, result.status.astype(np.int8)
    if normals is not None:
        d = np.asarray(directions, np.float32).reshape(-1, 3)[result.hit]
        nrm = np.asarray(normals, np.float32).copy()
        flip = np.einsum("ij,ij->i", nrm, d) > 0
        nrm[flip] *= -1
        out.normal[result.hit] = nrm
        out.normal_valid[result.hit] = normal_valid
    out.stats = {
        "field_evals": result.field_evals + int(normal_evals),
        "trace_steps": result.trace_steps,
        "backward_passes": int(backward_passes),
        "undecided": int((result.status == RayStatus.UNDECIDED).sum()),
        "host_syncs": int(result.host_syncs),
    }
    return out
