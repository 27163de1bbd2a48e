"""Device-resident sphere tracing: the tracer of ddfbench.evaluate.trace without the per-step host round trips.

`sphere_trace` (numpy in, numpy out) compacts its active set after every step and checks for sign changes
every step: about three device-to-host syncs a step, which on a GPU cost more than a small field's evaluation,
so a timing of it measures the loop rather than the method. `DeviceSphereTracer` traces the same fields by the
same rules with torch tensors that stay on the field's device:

* resident: rays in and depths out are device tensors (no numpy, no `.cpu()`); the per-ray march state
  (t, previous point, side sign, bracket, hit depth) lives on the device between calls of the step function;
* fused: one step function evaluates the field and updates every ray's state with `torch.where` (a ray that
  has stopped -- hit, sign change, left the box -- is frozen in place, still evaluated, until the next
  compaction); with `compiled=True` that function is `torch.compile`d (dynamic shapes) so the update is a few
  fused kernels;
* syncs: the march runs `sync_every` steps on the current active set, then compacts it with one `torch.nonzero`
  (whose size is also the early-exit check: an empty set ends the march). host_syncs = 1 (box clip) +
  at most ceil(max_steps / sync_every) - 1 (compactions) + 1 (gathering the bracketed rays), against
  sphere_trace's 2 + 2 to 3 a step;
* refinement: a ray whose step lands on the far side of the zero level (r <= -tol) keeps its bracket on the
  device; after the march the bracketed rays are refined together by exactly `refine_steps` Illinois
  (regula falsi) iterations, converged rays frozen by `torch.where` (no sync; trace._illinois compacts every
  iteration, one sync each, so it is not reused).

Same rules as sphere_trace (see ddfbench.evaluate.trace): box clip (core.geometry.box_entry; a ray missing the
box costs no evaluation), side sign from the first evaluation (a ray starting inside traces to the exit), hit
|r| < eps * t + eps_abs with the final free step t + r, far bound min(t_exit, t_max), sign change -> hit refined,
step cap max_steps -> undecided (t = inf). Not supported: over-relaxation (options.omega != 1 raises
InputError) and the start-offset escape phase: a ray whose first |f| < start_offset (a secondary ray leaving
a surface) is traced plainly from the side it starts on, so it may report the surface it starts on (its first
point is a hit when |f| < tol). That serves every preset's trace block in conf/model (grid_sdf, neural_sdf,
neural_sdf_tuned, neural_sdf_grid, gan_sdf, gan_sdf_tuned: all omega 1.0) and primary (camera) rays; not
experiment render_matched's omega = 1.6 runs nor shadow rays.

Counts differ from sphere_trace's by construction: field_evals counts every point handed to the field,
frozen rays included (up to sync_every - 1 extra evaluations per stopped ray) and refine_steps per bracketed ray.
"""

from __future__ import annotations

import math
from typing import Callable

import torch

from ddfbench.core.errors import InputError
from ddfbench.core.geometry import box_entry
from ddfbench.evaluate.trace import TorchField, TraceOptions, false_position

PRECISIONS = ("fp32", "tf32", "bf16")

# march state per active ray, in this order (all (M,) on the device):
# t, t_prev, r_prev, side (0 until the first evaluation, then +-1), t_far, done, t_hit (inf unless converged),
# crossed (sign change: bracket [t_prev, t] with values r_prev > 0 > fb), fb
State = tuple[torch.Tensor, ...]


class DeviceSphereTracer:
    """Sphere tracer whose loop stays on the field's device (see the module docstring).

    field: torch callable points (M, 3) float32 -> signed distance (M,) (negative inside), normalized units,
    on the device the rays will be on. domain: half-side of the field box [-domain, domain]^3.
    options: TraceOptions (omega must be 1; start_offset and escape_steps are ignored).
    precision: "fp32" (TF32 off), "tf32" (TF32 matmuls and convolutions on CUDA) or "bf16" (torch.autocast to
    bfloat16 around the field call only; the march state stays float32). torch's TF32 flags are restored after
    each call.
    eps_abs_bf16: the absolute hit tolerance used instead of options.eps_abs with bf16 only -- a named deviation:
    bf16 keeps 8 mantissa bits, so a field value near 0 carries errors of about 1e-3 and cannot meet 1e-6.
    compiled: torch.compile(dynamic=True) the march step (field evaluation + state update), built lazily on the
    first call; the refinement iterations run eagerly. Dynamic shapes still specialize sizes 0 and 1, so an active
    set of one ray takes the eager step (no recompile).
    sync_every: march steps between compactions of the active set (>= 1).

    After a call: field_evals (int: points evaluated in the march and the refinement), host_syncs (int: device-to-
    host round trips of the call), trace_steps (int: the march's share of field_evals).
    """

    def __init__(self, field: TorchField, domain: float, options: TraceOptions, precision: str = "fp32",
                 compiled: bool = False, sync_every: int = 8, eps_abs_bf16: float = 1e-3):
        options.check()
        if options.omega != 1.0:
            raise InputError(f"trace.omega {options.omega}: DeviceSphereTracer supports plain sphere tracing only (1.0)")
        if precision not in PRECISIONS:
            raise InputError(f"precision {precision!r}: unknown (fp32 | tf32 | bf16)")
        if int(sync_every) < 1:
            raise InputError(f"sync_every {sync_every}: must be at least 1")
        if not eps_abs_bf16 > 0:
            raise InputError(f"eps_abs_bf16 {eps_abs_bf16}: must be > 0")
        self.field, self.domain, self.options = field, float(domain), options
        self.precision, self.compiled, self.sync_every = precision, bool(compiled), int(sync_every)
        self.eps = float(options.eps)
        self.eps_abs = float(eps_abs_bf16 if precision == "bf16" else options.eps_abs)
        self._step: Callable[..., State] | None = None
        self.field_evals = 0
        self.trace_steps = 0
        self.host_syncs = 0

    # ---- field evaluation ----------------------------------------------------------------------------------
    def _eval(self, points: torch.Tensor) -> torch.Tensor:
        """Field at points (M, 3) -> (M,) float32; autocast to bfloat16 around the field only with bf16."""
        if self.precision == "bf16":
            with torch.autocast(device_type=points.device.type, dtype=torch.bfloat16):
                f = self.field(points)
        else:
            f = self.field(points)
        return f.reshape(-1).float()

    def _march_step(self, o: torch.Tensor, d: torch.Tensor, t: torch.Tensor, t_prev: torch.Tensor,
                    r_prev: torch.Tensor, side: torch.Tensor, t_far: torch.Tensor, done: torch.Tensor,
                    t_hit: torch.Tensor, crossed: torch.Tensor, fb: torch.Tensor) -> State:
        """One sphere-tracing step of every ray in the active set, stopped (done) rays frozen. All (M,) but
        o, d (M, 3). Returns the new (t, t_prev, r_prev, side, done, t_hit, crossed, fb)."""
        f = self._eval(o + t[:, None] * d)
        side = torch.where(side == 0, torch.where(f < 0, -1.0, 1.0), side)  # the first evaluation fixes the side
        r = side * f
        tol = self.eps * t + self.eps_abs
        live = ~done
        converged = live & (r.abs() < tol)
        cross = live & (r <= -tol)
        new_t = t + r
        advance = live & ~converged & ~cross
        past = advance & (new_t > t_far)  # left the box (or passed t_max): a miss
        advance = advance & ~past
        t_hit = torch.where(converged, t + r, t_hit)  # the final free step
        fb = torch.where(cross, r, fb)  # bracket [t_prev, t]: r_prev > 0 > r
        crossed = crossed | cross
        done = done | converged | cross | past
        t_prev = torch.where(advance, t, t_prev)
        r_prev = torch.where(advance, r, r_prev)
        t = torch.where(advance, new_t, t)  # stopped rays stay inside [t_enter, t_far]
        return t, t_prev, r_prev, side, done, t_hit, crossed, fb

    def _step_fn(self) -> Callable[..., State]:
        if self._step is None:
            self._step = torch.compile(self._march_step, dynamic=True) if self.compiled else self._march_step
        return self._step

    # ---- tracing -------------------------------------------------------------------------------------------
    def __call__(self, origins: torch.Tensor, directions: torch.Tensor) -> torch.Tensor:
        """Trace rays origins (N, 3) and unit directions (N, 3), float32 tensors on the field's device
        -> t (N,) float32 on that device: ray parameter (normalized units) of the hit, inf on a miss or an
        undecided ray."""
        if origins.ndim != 2 or origins.shape[1] != 3 or origins.shape != directions.shape:
            raise InputError(f"rays {tuple(origins.shape)}, {tuple(directions.shape)}: (N, 3) and (N, 3) needed")
        if origins.dtype != torch.float32 or directions.dtype != torch.float32:
            raise InputError(f"rays {origins.dtype}, {directions.dtype}: float32 needed")
        if origins.device != directions.device:
            raise InputError(f"rays on {origins.device} and {directions.device}: one device needed")
        cuda = origins.device.type == "cuda"
        saved = (torch.backends.cuda.matmul.allow_tf32, torch.backends.cudnn.allow_tf32)
        torch.backends.cuda.matmul.allow_tf32 = torch.backends.cudnn.allow_tf32 = cuda and self.precision == "tf32"
        try:
            with torch.no_grad():
                return self._trace(origins, directions)
        finally:
            torch.backends.cuda.matmul.allow_tf32, torch.backends.cudnn.allow_tf32 = saved

    def _trace(self, o_all: torch.Tensor, d_all: torch.Tensor) -> torch.Tensor:
        opt = self.options
        n = o_all.shape[0]
        t_out = torch.full((n,), math.inf, device=o_all.device)
        # per ray, written back at each compaction: the bracket of a sign change and its side
        crossed_all = torch.zeros(n, dtype=torch.bool, device=o_all.device)
        a_all, fa_all, b_all, fb_all, side_all = (torch.zeros(n, device=o_all.device) for _ in range(5))
        evals, syncs = 0, 0

        t_enter, t_exit, _ = box_entry(o_all, d_all, self.domain)
        t_far_all = t_exit.clamp_max(opt.t_max)
        idx = torch.nonzero(t_enter <= t_far_all).squeeze(1)  # rays that meet the box: the only ones evaluated
        syncs += 1
        m = idx.numel()
        o, d, t, t_far = o_all[idx], d_all[idx], t_enter[idx], t_far_all[idx]
        t_prev, r_prev, side, fb = t.clone(), torch.zeros_like(t), torch.zeros_like(t), torch.zeros_like(t)
        done, crossed = torch.zeros_like(t, dtype=torch.bool), torch.zeros_like(t, dtype=torch.bool)
        t_hit = torch.full_like(t, math.inf)

        def write_back() -> None:  # index_put with an index tensor: no sync
            t_out[idx] = t_hit
            crossed_all[idx] = crossed
            a_all[idx], fa_all[idx], b_all[idx], fb_all[idx], side_all[idx] = t_prev, r_prev, t, fb, side

        step_fn = self._step_fn() if m else None
        step = 0
        while m and step < opt.max_steps:
            fn = step_fn if m > 1 else self._march_step  # a compiled step specializes size 1: no recompile for it
            for _ in range(min(self.sync_every, opt.max_steps - step)):
                t, t_prev, r_prev, side, done, t_hit, crossed, fb = fn(o, d, t, t_prev, r_prev, side, t_far,
                                                                       done, t_hit, crossed, fb)
                evals += m
                step += 1
            write_back()
            if step >= opt.max_steps:
                break  # rays still marching are undecided: t_out stays inf
            keep = torch.nonzero(~done).squeeze(1)
            syncs += 1
            m = keep.numel()
            idx, o, d, t, t_far = idx[keep], o[keep], d[keep], t[keep], t_far[keep]
            t_prev, r_prev, side, fb = t_prev[keep], r_prev[keep], side[keep], fb[keep]
            done, t_hit, crossed = done[keep], t_hit[keep], crossed[keep]
        self.trace_steps = evals

        br = torch.nonzero(crossed_all).squeeze(1)
        syncs += 1
        if br.numel():
            root = self._refine(o_all[br], d_all[br], a_all[br], fa_all[br], b_all[br], fb_all[br], side_all[br])
            t_out[br] = root
            evals += br.numel() * opt.refine_steps
        self.field_evals, self.host_syncs = int(evals), int(syncs)
        return t_out

    def _refine(self, o: torch.Tensor, d: torch.Tensor, a: torch.Tensor, fa: torch.Tensor, b: torch.Tensor,
                fb: torch.Tensor, side: torch.Tensor) -> torch.Tensor:
        """Root of side * f on [a, b], fa > 0 > fb, by exactly options.refine_steps Illinois iterations on every
        bracketed ray; a ray stops at the first point on its own side within the hit tolerance (trace._illinois's
        rule) and is frozen by torch.where from then on, so no iteration syncs. -> t (M,)."""
        root = false_position(a, fa, b, fb)
        live = torch.ones_like(a, dtype=torch.bool)
        last = torch.zeros_like(a)  # +1: a moved last, -1: b moved last
        for _ in range(self.options.refine_steps):
            c = (a * fb - b * fa) / (fb - fa)
            c = torch.where(torch.isfinite(c) & (c > a) & (c < b), c, 0.5 * (a + b))
            fc = side * self._eval(o + c[:, None] * d)
            root = torch.where(live, c, root)
            out = fc > 0
            fb_h = torch.where(out & (last > 0), 0.5 * fb, fb)
            fa_h = torch.where(~out & (last < 0), 0.5 * fa, fa)
            a_n, fa_n = torch.where(out, c, a), torch.where(out, fc, fa_h)
            b_n, fb_n = torch.where(out, b, c), torch.where(out, fb_h, fc)
            a, fa = torch.where(live, a_n, a), torch.where(live, fa_n, fa)
            b, fb = torch.where(live, b_n, b), torch.where(live, fb_n, fb)
            last = torch.where(live, torch.where(out, 1.0, -1.0), last)
            live = live & (~out | (fc >= self.eps * c + self.eps_abs))
        return torch.where(live, false_position(a, fa, b, fb), root)
