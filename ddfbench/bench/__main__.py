"""python -m ddfbench.bench [--device cpu|cuda|auto] [--sizes small|default] [--repeats N] [--warmup N]
                            [--threads N] [--only sampling,oracle,...] [--out reports/bench]

Runs the sections (see ddfbench.bench), prints the table and writes bench-<device>-<sizes>.md and
.json into --out (default reports/bench; with --only, reports/bench/<sections>: reports/bench/crossover). A section that fails is reported as failed (its error in the table and the JSON)
and the command exits 1 after the others have run.
"""

from __future__ import annotations

import argparse
import copy
import datetime as dt
import importlib
import os
import signal
import sys
import tempfile
import threading
import time

import torch
import yaml

from ddfbench.bench import CUDA_ONLY_BY_DEFAULT, ON_REQUEST, SECTIONS
from ddfbench.bench.context import Context
from ddfbench.bench.results import SectionResult
from ddfbench.bench.sizes import SIZES
from ddfbench.bench.table import to_markdown, write
from ddfbench.core import heap
from ddfbench.core.errors import InputError, one_line
from ddfbench.fit.train import resolve_device
from ddfbench.run.checks import writable_folder
from ddfbench.run.runs import environment


def parse_sections(text: str) -> list[str]:
    names = [s.strip() for s in text.split(",") if s.strip()]
    unknown = [n for n in names if n not in SECTIONS]
    if unknown or not names:
        raise InputError(f"--only {text!r}: unknown section(s) {unknown} (known: {', '.join(SECTIONS)})")
    return [s for s in SECTIONS if s in names]


class Stopped(BaseException):
    """SIGTERM arrived (a timeout, a job scheduler): the section stops, and what it measured is written. A
    BaseException, so that a section's own `except Exception` (a family that failed, a run) does not swallow it."""


def _stop(signum, frame) -> None:
    signal.signal(signal.SIGTERM, signal.SIG_IGN)  # one stop is enough: a second SIGTERM must not cut the report
    raise Stopped("SIGTERM: the bench was stopped midway")


def run_section(name: str, ctx: Context) -> SectionResult:
    """One section; an exception becomes a failed SectionResult with a one-line error, holding the rows
    and details the section had put in ctx.partial before it failed."""
    start = time.perf_counter()
    ctx.partial = None
    try:
        result = importlib.import_module(f"ddfbench.bench.{name}").run(ctx)
    except (Exception, Stopped) as err:  # the other sections still run (unless stopped); the exit code says so
        result = ctx.partial or SectionResult()
        result.error = one_line(err)
    result.seconds = time.perf_counter() - start
    return result


def sized(sizes: dict, settings: list[str]) -> dict:
    """A copy of sizes ({section: {key: value}}) with each "section.key=value" (value in YAML) applied."""
    out = copy.deepcopy(sizes)
    for text in settings:
        name, eq, value = text.partition("=")
        section, _, key = name.partition(".")
        if not eq or key not in out.get(section, {}):
            raise InputError(f"--set {text!r}: expected SECTION.KEY=VALUE with a known section and key "
                             f"(race keys: {', '.join(out['race'])})")
        out[section][key] = yaml.safe_load(value)
    return out


def _slug(text: str) -> str:
    return "-".join(filter(None, "".join(c if c.isalnum() else "-" for c in text.lower()).split("-")))


def report_name(device: str, sizes: str, settings: list[str] = ()) -> str:
    """bench-cpu-<sizes>, or on CUDA bench-cuda-<gpu> (e.g. bench-cuda-nvidia-h100-80gb-hbm3; -<sizes> unless
    default); then each --set, so that a changed run does not overwrite the plain one (…-race-capacities-false)."""
    if not device.startswith("cuda"):
        parts = [f"bench-cpu-{sizes}"]
    else:
        parts = ["bench-cuda", _slug(torch.cuda.get_device_name(torch.device(device)))] + ([sizes] if sizes != "default" else [])
    return "-".join(parts + [_slug(text) for text in settings])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ddfbench.bench", description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu", help="cpu | cuda | auto (torch work; open3d and scipy stay on the CPU)")
    ap.add_argument("--sizes", default="default", choices=sorted(SIZES),
                    help="problem sizes (small: seconds, for tests)")
    ap.add_argument("--repeats", type=int, default=9, help="timed warm calls per figure (median and IQR)")
    ap.add_argument("--warmup", type=int, default=1, help="untimed calls after the cold one")
    ap.add_argument("--threads", type=int, default=0,
                    help="torch threads (0: torch's default), on which the mesh family's open3d BVH casts too; "
                         "sampling's open3d and scipy use every core")
    ap.add_argument("--only", default=None, help="comma-separated sections to run (default: all but "
                    f"{', '.join(ON_REQUEST)}; on a CPU device also not {', '.join(CUDA_ONLY_BY_DEFAULT)})")
    ap.add_argument("--oracle-backend", default="open3d", choices=("open3d", "warp"),
                    help="the ground truth's backend (warp: every query through Warp, for a machine without open3d)")
    ap.add_argument("--out", default=None, help="folder for the .md and .json (default: reports/bench; with --only, "
                    "reports/bench/<its sections>, so that a part never replaces the whole bench)")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                    help="override one size of a section (VALUE in YAML), e.g. race.capacities=false; repeatable")
    args = ap.parse_args(argv)
    try:
        device = resolve_device(args.device, "--device")
        sizes = sized(SIZES[args.sizes], args.set)
        sections = parse_sections(args.only if args.only is not None else ",".join(
            s for s in SECTIONS if s not in ON_REQUEST and (device.startswith("cuda") or s not in CUDA_ONLY_BY_DEFAULT)))
        if args.repeats < 1 or args.warmup < 0 or args.threads < 0:
            raise InputError(f"--repeats {args.repeats} / --warmup {args.warmup} / --threads {args.threads}: "
                             "need repeats >= 1, warmup >= 0, threads >= 0")
        out = args.out or os.path.join("reports", "bench", *(["-".join(sections)] if args.only is not None else []))
        writable_folder(out, "--out ")
    except InputError as err:
        print(f"ddfbench.bench: {err}", file=sys.stderr)
        return 2

    if args.threads:
        torch.set_num_threads(args.threads)
    threads = torch.get_num_threads()
    heap_kept = heap.keep_freed_blocks()  # as a run sets it (ddfbench.run.runner)
    started, t0 = dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"), time.perf_counter()
    load = round(os.getloadavg()[0], 2) if hasattr(os, "getloadavg") else None
    results: dict[str, SectionResult] = {}
    main_thread = threading.current_thread() is threading.main_thread()  # signal handlers live there only
    previous = signal.signal(signal.SIGTERM, _stop) if main_thread else None
    try:
        with tempfile.TemporaryDirectory(prefix="ddfbench-bench-") as workdir:
            shared = Context(device, {}, args.repeats, args.warmup, workdir, threads, oracle_backend=args.oracle_backend)
            for name in sections:
                print(f"[bench] {name} ...", file=sys.stderr, flush=True)
                shared.sizes = sizes[name]
                results[name] = run_section(name, shared)
                failed = f" FAILED {results[name].error}" if results[name].error else ""
                print(f"[bench] {name}: {results[name].seconds:.1f} s{failed}", file=sys.stderr, flush=True)
                if results[name].error and results[name].error.startswith(Stopped.__name__):
                    break  # the sections not started are left out of the report
    except Stopped:
        pass  # stopped between sections: the report holds those that ran
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)
    doc = {
        "command": " ".join(["python -m ddfbench.bench", *(argv if argv is not None else sys.argv[1:])]),
        "started": started, "total_s": time.perf_counter() - t0, "load_average_start": load,
        "options": {"device": device, "sizes": args.sizes, "repeats": args.repeats, "warmup": args.warmup,
                    "sections": sections, "oracle_backend": args.oracle_backend},
        "env": {**environment(device, threads), "glibc_heap_kept": heap_kept},
        "sizes": {name: sizes[name] for name in sections},
        "sections": {name: r.as_dict() for name, r in results.items()},
    }
    print(to_markdown(doc))
    md, js = write(doc, out, report_name(device, args.sizes, args.set))
    print(f"[bench] wrote {md} and {js}", file=sys.stderr)
    return 1 if any(r.error for r in results.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
