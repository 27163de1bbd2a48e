"""Section 8, end to end: whole commands (`python -m ddfbench ...`: the default run, the smoke sweep)
in a fresh output folder, wall time per stage.

Each command runs once in a subprocess, as a user types it plus force=true, an empty out_dir and
train.device = --device (threads: the runner's default; each row shows the records' own). The stage
times come from the records it writes (cost: sampling_s, or load_s on a dataset cache hit; fit_s,
the training itself; probes = fit_wall_s - fit_s, the accuracy probes during the fit; extract_s;
metrics_s; render_cold_s + render_repeats x render_warm_s), summed over its jobs; each is set beside
the command's wall time (ratio = its share). "other" is the rest: process start and imports, Hydra,
mesh export, reference renders, render warm-up and record writing.
Sizes: runs, a list of {name, args}.
"""

from __future__ import annotations

import os
import subprocess
import sys

from ddfbench.bench.context import Context
from ddfbench.bench.results import SectionResult, compare
from ddfbench.bench.timing import once
from ddfbench.run.runs import find_records

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def stage_seconds(records: list[dict]) -> dict[str, float]:
    """Seconds per stage summed over the jobs' records."""
    out = {"sampling": 0.0, "fit": 0.0, "probes": 0.0, "extract": 0.0, "metrics": 0.0, "render": 0.0}
    for rec in records:
        c, smp = rec.get("cost") or {}, rec.get("sampling") or {}
        out["sampling"] += float(smp.get("load_s", 0.0) if smp.get("cache_hit") else c.get("sampling_s", 0.0))
        out["fit"] += float(c.get("fit_s", 0.0))
        out["probes"] += max(float(c.get("fit_wall_s", 0.0)) - float(c.get("fit_s", 0.0)), 0.0)
        out["extract"] += float(c.get("extract_s", 0.0))
        out["metrics"] += float(c.get("metrics_s", 0.0))
        out["render"] += float(c.get("render_cold_s", 0.0)) + \
            int(c.get("render_repeats", 0)) * float(c.get("render_warm_s", 0.0))
    return out


def error_line(proc: subprocess.CompletedProcess) -> str:
    """The last line of a failed command's output that is not Hydra's HYDRA_FULL_ERROR hint."""
    lines = [ln for ln in (proc.stderr + proc.stdout).strip().splitlines() if ln and "HYDRA_FULL_ERROR" not in ln]
    return lines[-1] if lines else "no output"


def run_command(args: list[str], out_dir: str, device: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "ddfbench", *args, f"out_dir={out_dir}", "force=true", "quiet=true",
           f"train.device={device}"]
    return subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, env=dict(os.environ, PYTHONUNBUFFERED="1"))


def run(ctx: Context) -> SectionResult:
    result = SectionResult()
    for i, spec in enumerate(ctx.sizes["runs"]):
        name, args = spec["name"], list(spec["args"])
        out_dir = os.path.join(ctx.workdir, f"end_to_end_{i}")
        proc, wall = once(lambda: run_command(args, out_dir, ctx.device), device=ctx.device)
        if proc.returncode != 0:
            result.notes.append(f"`python -m ddfbench {' '.join(args)}` exited {proc.returncode}: {error_line(proc)}")
            continue
        records = find_records(out_dir)
        stages = stage_seconds(records)
        stages["other"] = max(wall.median_s - sum(stages.values()), 0.0)
        threads = max((int((r.get("env") or {}).get("threads") or 0) for r in records), default=0)
        result.details[name] = {"args": args, "wall": wall.as_dict(), "jobs": len(records),
                                "failed_jobs": sum(r.get("status") != "ok" for r in records), "stages_s": stages}
        failed = [f"{r.get('model')}: {r.get('error')}" for r in records if r.get("status") != "ok"]
        if failed:
            result.notes.append(f"{name}: {len(failed)} of {len(records)} jobs failed ({'; '.join(failed[:3])})")
        for stage, seconds in stages.items():
            if seconds > 0:
                result.rows.append(compare(
                    "end_to_end", f"{name} ({len(records)} jobs): {stage} seconds", seconds, "s",
                    f"the command's wall seconds ({wall.median_s:.1f} s)", wall.median_s, device=ctx.device,
                    threads=threads, note="ratio = share of the wall time"))
    if not result.rows:
        raise RuntimeError("no command finished: " + "; ".join(result.notes))
    return result
