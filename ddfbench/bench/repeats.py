"""python -m ddfbench.bench.repeats RUN.json [RUN.json ...] [--out FOLDER]

The race (ddfbench.bench.race) repeated in fresh processes with distinct ray seeds, pooled (issue 51). Every
ratio is formed inside one run, from two rates measured side by side on the same rays; across runs each
ratio gets its median, mean ± std and the 95 % t-interval of the mean (ddfbench.report.stats), with the
per-run values by ray seed. Pooled: the fastest DDF against each other contestant on both ray sets, the
device-resident SDF tracers against the numpy loop, every capacity against the BVH and the LODs raced beside
it (with depth error and the share of the dense bf16 product's rate), and the cold costs. Writes
repeats.md and repeats.json into --out (default: the first run's folder).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
import sys

from ddfbench.bench.results import precision_of
from ddfbench.core.errors import InputError
from ddfbench.report.stats import sig3, summarize_values

SETS = ("primary", "incoherent")
REFERENCES = ("warp_bvh", "embree_all_cores", "neural_sdf_trace", "grid_sdf_trace")


def load_race(path: str) -> dict:
    """The race section's details of one bench JSON (a race stopped by SIGTERM keeps what it measured: "_stopped"
    says so); a one-line InputError naming the file when it has none or the race failed otherwise."""
    try:
        with open(path) as fh:
            doc = json.load(fh)
        race = doc["sections"]["race"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(f"{path}: not a bench JSON with a race section ({type(exc).__name__}: {exc})") from None
    error = race.get("error") or ""
    if error and not error.startswith("Stopped"):
        raise InputError(f"{path}: its race failed ({error})")
    return {**race["details"], "_gpu": doc.get("env", {}).get("gpu"), "_commit": doc.get("env", {}).get("git_sha"),
            "_stopped": bool(error)}


def check_same_networks(runs: list[dict], paths: list[str]) -> None:
    """A one-line InputError unless every run raced the same prepared networks (details' "prepared" names of the DDF,
    the neural SDF and each capacity, where the runs loaded them: pooling runs of different networks would mix two
    experiments)."""
    levels = dict.fromkeys(level for r in runs for level in (r.get("capacities") or {}))
    names = {part: {str((r.get(part) or {}).get("prepared")) for r in runs} for part in ("ddf", "neural_sdf")}
    names.update({f"capacity {level}": {str(r["capacities"][level].get("prepared")) for r in runs
                                        if level in (r.get("capacities") or {})} for level in levels})  # as reached
    for part, found in names.items():
        if len(found) > 1:
            raise InputError(f"{', '.join(paths)}: the runs raced different {part} networks ({sorted(found)})")


def ratios(run: dict) -> dict[str, float]:
    """{quantity: value} of one run: rates and ratios of rates measured side by side in that run."""
    out: dict[str, float] = {}
    for set_name in SETS:
        d = run.get(set_name)
        if not d or "fastest" not in d:  # not raced, or stopped while its figures were written
            continue
        # by role, so that a run whose fastest variant differs still pools (fastest_names says which it was)
        roles = {"DDF": d["fastest"]["ddf"], **{f"{kind} SDF device tracer": d["fastest"][f"{kind}_sdf"]
                                                 for kind in ("neural", "grid") if f"{kind}_sdf" in d["fastest"]},
                 **{r: r for r in REFERENCES if r in d}}
        rate = d[roles["DDF"]]["rays_per_s"]
        out[f"{set_name}: DDF rays/s"] = rate
        for role, name in roles.items():
            if role != "DDF":
                out[f"{set_name}: DDF / {role}"] = rate / d[name]["rays_per_s"]
        if "neural SDF device tracer" in roles and "ddf_bf16" in d:  # the method's gap without the DDF's fusion
            out[f"{set_name}: unfused bf16 DDF / neural SDF device tracer"] = (
                d["ddf_bf16"]["rays_per_s"] / d[roles["neural SDF device tracer"]]["rays_per_s"])
        bare = f"ddf_bare_{precision_of(roles['DDF'])}"
        out[f"{set_name}: DDF / its bare forward"] = rate / d[bare]["rays_per_s"]
        for kind, loop in (("neural", "neural_sdf_trace"), ("grid", "grid_sdf_trace")):
            if f"{kind} SDF device tracer" in roles and loop in roles:
                out[f"{set_name}: {kind} SDF device tracer / {loop}"] = (
                    d[roles[f"{kind} SDF device tracer"]]["rays_per_s"] / d[loop]["rays_per_s"])
        for role in (r for r in ("DDF", "warp_bvh", "neural SDF device tracer", "grid SDF device tracer",
                                 "neural_sdf_trace", "grid_sdf_trace") if r in roles):
            out[f"{set_name}: depth MAE {role}"] = d[roles[role]]["depth_mae"]
            out[f"{set_name}: mask IoU {role}"] = d[roles[role]]["mask_iou"]
    for level, c in (run.get("capacities") or {}).items():
        if "fastest" not in c:
            continue
        tag = f"capacity {level} ({c['width']}x{c['depth']})"
        best = c["fastest"]
        out[f"{tag}: DDF rays/s"] = c[best]["rays_per_s"]
        meshes = [k for k in c if k == "warp_bvh" or k.startswith("mesh_lod_")]
        for m in meshes:
            out[f"{tag}: DDF / {m}"] = c[best]["rays_per_s"] / c[m]["rays_per_s"]
        out[f"{tag}: depth MAE"] = c[best]["depth_mae"]
        out[f"{tag}: mask IoU"] = c[best]["mask_iou"]
        if "share_of_dense_bf16" in c:
            out[f"{tag}: TFLOP/s"] = c["tflops"]
            out[f"{tag}: share of the dense bf16 product"] = c["share_of_dense_bf16"]
    first = next(iter((run.get("capacities") or {}).values()), {})
    for m in (k for k in first if k.startswith("mesh_lod_")):
        out[f"{m}: depth MAE (primary)"] = first[m]["depth_mae"]
        out[f"{m}: mask IoU (primary)"] = first[m]["mask_iou"]
    for key, seconds in (run.get("cold") or {}).items():
        out[f"cold: {key}"] = seconds
    primary = run.get("primary") or {}
    for name, v in primary.items():
        if isinstance(v, dict) and "cold_s" in v:
            out[f"cold: first call {name} (primary)"] = v["cold_s"]
    if "dense_bf16_tflops" in run:
        out["dense bf16 8192^3 product TFLOP/s"] = run["dense_bf16_tflops"]
    return out


def fastest_names(runs: list[dict]) -> dict[str, list[str]]:
    """{"primary: DDF": [the fastest variant's name in each run], ...}: which variant a role's figures are of."""
    out: dict[str, list[str]] = {}
    for set_name in SETS:
        for role in ("ddf", "neural_sdf", "grid_sdf"):
            names = [r[set_name]["fastest"][role] for r in runs if role in r.get(set_name, {}).get("fastest", {})]
            if names:
                out[f"{set_name}: {role}"] = names
    levels = dict.fromkeys(level for r in runs for level in (r.get("capacities") or {}))
    for level in levels:
        names = [r["capacities"][level]["fastest"] for r in runs if "fastest" in (r.get("capacities") or {}).get(level, {})]
        if names:
            out[f"capacity {level}"] = names
    return out


def is_ratio(quantity: str) -> bool:
    """A ratio of two rates (its runs pool as a geometric mean too)."""
    return " / " in quantity


def pool(runs: list[dict]) -> list[dict]:
    """One row per quantity found in any run (a stopped or shorter run may lack some): n, median, mean, std and
    95 % interval of the finite values (no std or interval for n = 1; the interval cut at 0, and at 1 for IoUs and
    shares; none for cold costs, whose runs mix first launches and relaunches), for ratios also the geometric mean
    and the interval of the logs (gmean, glo, ghi: what claims.md quotes), and the values by ray seed."""
    per_run = [ratios(r) for r in runs]
    seeds = [str(r.get("ray_seed")) for r in runs]
    keys = list(dict.fromkeys(k for p in per_run for k in p))
    rows = []
    for key in keys:
        values = {seed: p[key] for seed, p in zip(seeds, per_run) if key in p}
        finite = [v for v in values.values() if v is not None and math.isfinite(v)]
        s = summarize_values(finite)
        lo, hi = max(s.lo, 0.0), (min(s.hi, 1.0) if "IoU" in key or "share" in key else s.hi)
        if key.startswith("cold:"):
            lo = hi = math.nan
        row = {"quantity": key, "n": s.n, "median": statistics.median(finite) if finite else math.nan,
               "mean": s.mean, "std": s.std, "lo": lo if s.n > 1 else math.nan, "hi": hi if s.n > 1 else math.nan,
               "values": values}
        if is_ratio(key):
            g = summarize_values(math.log(v) for v in finite if v > 0)
            row.update(gmean=math.exp(g.mean), glo=math.exp(g.lo), ghi=math.exp(g.hi))
        rows.append(row)
    return rows


def verdicts(rows: list[dict]) -> list[str]:
    """The capacity claim: the most accurate capacity measured in two runs or more whose DDF / warp_bvh interval
    (geometric) lies above 1 (or that none does), and the LODs' depth error and speed against it."""
    by = {r["quantity"]: r for r in rows}
    caps = sorted({q.split(":")[0] for q, r in by.items()
                   if q.startswith("capacity ") and q.endswith(": DDF / warp_bvh") and r["n"] >= 2})
    faster = [c for c in caps if by[f"{c}: DDF / warp_bvh"]["glo"] > 1.0]
    lines = [f"Capacities measured in two runs or more: {', '.join(caps) or 'none'}."]
    if not faster:
        lines.append("No DDF capacity measured is faster than the BVH with its whole 95 % interval above 1.")
    else:
        best = min(faster, key=lambda c: by[f"{c}: depth MAE"]["median"])
        r, mae = by[f"{best}: DDF / warp_bvh"], by[f"{best}: depth MAE"]
        lines.append(f"The most accurate of them faster than the BVH: {best}, {_geo(r)} the BVH's rays/s, depth MAE "
                     f"{mae['median']:.2e} (median; {r['n']} runs).")
        for q in (q for q in by if q.startswith(f"{best}: DDF / mesh_lod_")):
            lod = q.split("/ ")[1]
            lod_mae = by.get(f"{lod}: depth MAE (primary)")
            if lod_mae:
                lines.append(f"- {lod}: depth MAE {lod_mae['median']:.2e} ({lod_mae['median'] / mae['median']:.3g}x the "
                             f"DDF's); the DDF answers {_geo(by[q])} its rays/s.")
    return lines


def _geo(row: dict) -> str:
    """'3.35x [2.44, 4.59] (geometric mean)' of a ratio row."""
    return f"{sig3(row['gmean'])}x [{sig3(row['glo'])}, {sig3(row['ghi'])}] (geometric mean)"


def _fmt(x: float) -> str:
    if x is None or not math.isfinite(x):
        return "–"
    return f"{x:.3g}" if 1e-2 <= abs(x) < 1e5 else f"{x:.2e}"


def to_markdown(runs: list[dict], rows: list[dict], paths: list[str]) -> str:
    stopped = [str(r.get("ray_seed")) for r in runs if r.get("_stopped")]
    head = [f"# The race repeated: {len(runs)} fresh processes, ray seeds {', '.join(str(r.get('ray_seed')) for r in runs)}",
            "", f"GPU: {', '.join(sorted({str(r.get('_gpu') or 'none (CPU)') for r in runs}))}; runs (commit): "
            + ", ".join(f"`{os.path.basename(p)}` ({str(r.get('_commit'))[:7]})" for p, r in zip(paths, runs)) + "."
            + (f" Stopped by their time limits, pooling what they measured before: seeds {', '.join(stopped)}."
               if stopped else ""), "",
            "Each value is formed inside one run from rates measured side by side on the same rays; across runs: "
            "median, mean ± std, and the 95 % t-interval of the mean in brackets (`python -m ddfbench.bench.repeats`); "
            "for ratios also the geometric mean with the t-interval of the logs (what `reports/claims.md` quotes). "
            "Cold rows: read them by seed; where the first run started with empty compile caches (Triton, "
            "inductor, Warp) and the later ones found them on disk, only the first is a first launch and the "
            "median is a relaunch's.",
            "", *verdicts(rows), "", "The fastest variant in each run (the role's figures are its): "
            + "; ".join(f"{k} {', '.join(sorted(set(v)))}" for k, v in fastest_names(runs).items()) + ".", "",
            "| quantity | n | median | mean ± std | 95 % interval | geometric mean [95 %] | by ray seed |",
            "|---|---|---|---|---|---|---|"]
    body = [f"| {r['quantity']} | {r['n']} | {_fmt(r['median'])} | {_fmt(r['mean'])} ± {_fmt(r['std'])} | "
            f"[{_fmt(r['lo'])}, {_fmt(r['hi'])}] | "
            + (f"{_fmt(r['gmean'])} [{_fmt(r['glo'])}, {_fmt(r['ghi'])}]" if "gmean" in r else "")
            + f" | {', '.join(f'{k}: {_fmt(v)}' for k, v in r['values'].items())} |" for r in rows]
    return "\n".join(head + body) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ddfbench.bench.repeats", description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="bench JSON files, one per process")
    ap.add_argument("--out", default=None, help="folder for repeats.md and repeats.json (default: the first run's)")
    args = ap.parse_args(argv)
    try:
        runs = [load_race(p) for p in args.runs]
        seeds = [r.get("ray_seed") for r in runs]
        if len(set(seeds)) != len(seeds):
            raise InputError(f"ray seeds {seeds}: each run needs its own (--set race.ray_seed=K)")
        check_same_networks(runs, args.runs)
    except InputError as err:
        print(f"ddfbench.bench.repeats: {err}", file=sys.stderr)
        return 2
    rows = pool(runs)
    out = args.out or os.path.dirname(os.path.abspath(args.runs[0]))
    os.makedirs(out, exist_ok=True)
    md = to_markdown(runs, rows, args.runs)
    with open(os.path.join(out, "repeats.md"), "w") as fh:
        fh.write(md)
    with open(os.path.join(out, "repeats.json"), "w") as fh:
        json.dump({"runs": [os.path.basename(p) for p in args.runs], "seeds": seeds,
                   "commits": [str(r.get("_commit"))[:7] for r in runs], "gpu": sorted({str(r.get("_gpu")) for r in runs}),
                   "references": [r.get("reference") for r in runs], "rows": rows}, fh, indent=1)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
