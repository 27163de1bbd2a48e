"""Section 3, DDF ray answering: DDF.intersect against the bare network on the same rays, and against
Embree (the mesh family) on the same rays: the DDF paper's speed claim, measured here.

Rays: one pinhole camera looking at the shape (ddfbench.bench.views.view_rays). The DDF is the
conf/model/ddf.yaml preset (sizes may override width/depth) with untrained weights: the cost of a
forward pass does not depend on the weights' values. Its visibility head is biased so that every ray
is a hit, the worst case for normal work (every ray then needs a backward pass).

References, measured in the same process:
- bare forward: the network on the box-entry points of the same rays, already torch tensors on the
  device, no grad, in eval_batch chunks: what answering distance + visibility has to cost at least;
- bare forward + backward: the same with grad and one backward pass for grad_x phi (normals);
- Embree: the mesh family (open3d RaycastingScene, Embree inside) and embreex on the same rays.
Sizes: shape, px (image side), model overrides (e.g. width, depth, eval_batch).
"""

from __future__ import annotations

import torch

from ddfbench.bench.context import DOMAIN, Context, preset
from ddfbench.bench.results import SectionResult, Target, compare
from ddfbench.bench.timing import measure_side_by_side, precisions
from ddfbench.bench.views import view_rays
from ddfbench.core.geometry import box_entry
from ddfbench.models.ddf import DDF
from ddfbench.render import mesh_reference

TARGET = Target(">=", 0.8)
ALL_HIT_BIAS = 20.0  # visibility logit bias: sigmoid(20) = 1 - 2e-9


def make_ddf(overrides: dict, device: str, name: str = "ddf") -> DDF:
    """The DDF preset `name` (conf/model/<name>.yaml) with overrides, untrained, every ray visible, on `device`."""
    rep = DDF(preset("model", name, **overrides))
    with torch.no_grad():
        if rep.net.out.out_features > 1:  # visibility head: logit is output 1
            rep.net.out.bias[1] = ALL_HIT_BIAS
    rep.net.to(device).eval()
    rep.device = device
    return rep


def bare_forward(net: torch.nn.Module, x: torch.Tensor, d: torch.Tensor, batch: int, backward: bool = False,
                 dtype: torch.dtype | None = None) -> None:
    """The network alone on points x (N, 3) and unit directions d (N, 3) in chunks of `batch`; with backward,
    grad_x of the distance by one backward pass per chunk; with dtype (torch.bfloat16), under autocast."""
    with torch.autocast(x.device.type, dtype=dtype or torch.float32, enabled=dtype is not None):
        for s in range(0, len(x), batch):
            if backward:
                xs = x[s:s + batch].detach().requires_grad_(True)
                t, _ = net(xs, d[s:s + batch])
                torch.autograd.grad(t.sum(), xs)
            else:
                with torch.no_grad():
                    net(x[s:s + batch], d[s:s + batch])


def run(ctx: Context) -> SectionResult:
    s = ctx.sizes
    o, d = view_rays(int(s["px"]))
    n = len(o)
    t_entry, _, meets = box_entry(o, d, DOMAIN)
    x_np = o[meets] + t_entry[meets, None] * d[meets]
    result = SectionResult(details={"rays": n, "rays_meeting_box": int(meets.sum())})
    rep = make_ddf(dict(s.get("model") or {}), ctx.device)
    x = torch.as_tensor(x_np, device=ctx.device)
    dd = torch.as_tensor(d[meets], device=ctx.device)
    batch = int(rep.cfg["eval_batch"])
    result.details["model"] = {k: rep.cfg[k] for k in ("width", "depth", "param", "pos_freqs", "dir_freqs",
                                                        "eval_batch")}
    result.details["n_params"] = rep.n_params()

    meshes = {backend: mesh_reference(ctx.shape(s["shape"]).mesh, DOMAIN, backend=backend)
              for backend in ("open3d", "embree")}
    for prec in precisions(ctx.device):
        kw = dict(device=ctx.device, precision=prec)
        for normals in (False, True):
            what = "distance + visibility + normals" if normals else "distance + visibility"
            fns = {"ddf": lambda: rep.intersect(o, d, normals=normals),
                   "bare": lambda: bare_forward(rep.net, x, dd, batch, normals)}
            fns.update({f"mesh_{b}": (lambda m=m: m.intersect(o, d, normals=normals)) for b, m in meshes.items()})
            try:
                timed = measure_side_by_side(fns, ctx.repeats, ctx.warmup, **kw)
            except (RuntimeError, TypeError) as err:  # a reduced precision the family cannot take (bf16 -> numpy)
                if prec == "fp32":
                    raise
                result.notes.append(f"{prec}, {what}: not supported ({str(err).splitlines()[0]})")
                continue
            hits, ddf_t = timed["ddf"]
            for name, (_, timing) in timed.items():
                result.details[f"{name}_{prec}_normals={normals}"] = timing.as_dict()
            result.details[f"ddf_{prec}_normals={normals}"]["hit_share"] = float(hits.hit.mean())
            result.rows.append(compare(
                "ddf", f"DDF.intersect rays/s, {what}", ddf_t.rate(n), "rays/s",
                "bare network forward" + (" + backward" if normals else "") + " rays/s, same rays",
                timed["bare"][1].rate(n), target=TARGET, threads=ctx.threads, **kw))
            for backend, label in (("open3d", "open3d Embree"), ("embree", "embreex")):
                result.rows.append(compare(
                    "ddf", f"DDF.intersect rays/s, {what}", ddf_t.rate(n), "rays/s",
                    f"mesh family ({label}, CPU) rays/s" + (" with normals" if normals else "") + ", same rays",
                    timed[f"mesh_{backend}"][1].rate(n), threads=ctx.threads, **kw,
                    note="the DDF paper's speed claim; above 1 means the DDF is faster"))
    return result
