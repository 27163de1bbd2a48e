"""Run records: schema version, config key, atomic write, resume.

A run writes <out_dir>/<experiment>/<key>/record.json by temporary file + rename, so a
reader (or a run killed with SIGKILL) sees either no record or a complete one.
"""

from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import platform
import socket
import subprocess
import sys
from typing import Any, Mapping

from ddfbench.core.atomic import write_atomic
from ddfbench.core.errors import one_line

SCHEMA_VERSION = 1

# Top-level config keys that do not change results: paths, resume flags, worker counts, logging, tracking.
NON_SEMANTIC_KEYS = ("out_dir", "force", "threads", "quiet", "experiment_name", "hydra", "tracking", "objective",
                     "checkpoint_every")

RECORD_FIELDS = (
    "schema_version", "key", "status", "error", "experiment", "family", "model", "shape", "sampling",
    "scene", "metrics", "cost", "counts", "artifacts", "flags", "config", "overrides", "env", "started", "finished",
)


def semantic_config(cfg: Mapping[str, Any]) -> dict[str, Any]:
    """The resolved config minus non-semantic keys."""
    return {k: v for k, v in cfg.items() if k not in NON_SEMANTIC_KEYS}


def input_digests(cfg: Mapping[str, Any]) -> dict[str, str]:
    """{setting: sha256 of the file's bytes} for every input file the job reads (a user mesh, shape.path) that
    exists; a missing file is left to the run that reads it (its failed record names it)."""
    path = (cfg.get("shape") or {}).get("path")
    if not path or not os.path.isfile(str(path)):
        return {}
    h = hashlib.sha256()
    try:
        with open(str(path), "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    except OSError:  # unreadable: the run that reads it fails with the file's own error
        return {}
    return {"shape.path": h.hexdigest()}


def config_key(cfg: Mapping[str, Any]) -> str:
    """16 hex chars: sha256 of the semantic config (canonical JSON), the schema version and the contents of
    the job's input files (input_digests: a changed mesh file is a new run)."""
    inputs = input_digests(cfg)
    blob = json.dumps({"schema": SCHEMA_VERSION, "config": semantic_config(cfg), **({"inputs": inputs} if inputs else {})},
                      sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


RECORD_FILE = "record.json"  # in each run folder
LOCK_FILE = "run.lock"  # in each run folder: held while one process runs the key (filelock)


def run_dir(out_dir: str, experiment: str, key: str) -> str:
    """The folder of one run: <out_dir>/<experiment>/<config key>."""
    return os.path.join(out_dir, experiment, key)


def record_path(out_dir: str, experiment: str, key: str) -> str:
    """Where the run's record lives: <run_dir>/record.json."""
    return os.path.join(run_dir(out_dir, experiment, key), RECORD_FILE)


def _json_safe(value: Any) -> Any:
    """Replace non-finite floats by strings ("inf", "nan") so the file is strict JSON."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    if isinstance(value, dict):
        return {str(k): _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if hasattr(value, "item") and callable(value.item):  # numpy scalars
        return _json_safe(value.item())
    return value


def write_json_atomic(path: str, data: Mapping[str, Any]) -> None:
    """Write JSON whole or not at all (core.atomic: a temporary file in the same folder, fsync, rename over path)."""
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    write_atomic(path, lambda fh: json.dump(_json_safe(dict(data)), fh, indent=1, allow_nan=False))


def record_problem(rec: Mapping[str, Any]) -> str | None:
    """What makes a parsed record.json not a run record (the fields every report and check reads), else None."""
    if rec.get("status") not in ("ok", "failed"):
        return f"status {rec.get('status')!r} is not 'ok' or 'failed'"
    for field, kind in (("key", str), ("experiment", str), ("metrics", dict), ("cost", dict), ("config", dict),
                        ("shape", dict)):
        if not isinstance(rec.get(field), kind):
            return f"field {field!r} is {'missing' if field not in rec else type(rec[field]).__name__}, not a {kind.__name__}"
    return None


def load_record(path: str) -> tuple[dict[str, Any] | None, str | None]:
    """(the record at path, None), or (None, what is wrong with the file); (None, None) where there is none."""
    try:
        with open(path, encoding="utf-8") as fh:
            rec = json.load(fh)
    except FileNotFoundError:
        return None, None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        return None, f"not a readable JSON file ({one_line(exc)})"
    if not isinstance(rec, dict):
        return None, f"holds a JSON {type(rec).__name__}, not a run record (an object)"
    problem = record_problem(rec)
    return (None, f"not a run record: {problem}") if problem else (rec, None)


def read_record(path: str) -> dict[str, Any] | None:
    """The record at path, or None where there is none or it is not one (a rerun writes it anew)."""
    return load_record(path)[0]


def schema_problem(rec: Mapping[str, Any]) -> str | None:
    """Why a record is not of the current schema (what is_done reads: a sweep runs it again), else None."""
    if rec.get("schema_version") == SCHEMA_VERSION:
        return None
    found = f"schema_version {rec['schema_version']!r}" if "schema_version" in rec else "no schema_version"
    return f"{found}, not {SCHEMA_VERSION} (a sweep runs it again)"


def is_done(path: str) -> bool:
    """True where an ok record of the current schema exists (the run is skipped unless forced)."""
    rec = read_record(path)
    return bool(rec) and rec.get("status") == "ok" and rec.get("schema_version") == SCHEMA_VERSION


def find_records(root: str) -> list[dict[str, Any]]:
    """Every record.json below root (any depth), each with its own folder under "_dir". A file that is not
    a record (cut short, not UTF-8, not a JSON object, another schema or none) is left out with a line on stderr naming it,
    as is a second record of a key already found (a copied run folder: the first in folder order stays)."""
    out, seen = [], {}
    for folder, dirs, files in os.walk(root):
        dirs.sort()
        if RECORD_FILE not in files:
            continue
        path = os.path.join(folder, RECORD_FILE)
        rec, problem = load_record(path)
        if rec is not None and (other := schema_problem(rec)):
            problem = other
        elif rec is not None and (first := seen.get((rec["experiment"], rec["key"]))) is not None:
            problem = f"a second record of run {rec['experiment']}/{rec['key']} (the first: {first})"
        if problem:
            print(f"ddfbench: skipped {path}: {problem}", file=sys.stderr)
        elif rec is not None:
            seen[(rec["experiment"], rec["key"])] = path
            rec["_dir"] = folder
            out.append(rec)
    return sorted(out, key=lambda r: (r.get("experiment", ""), r.get("key", "")))


CODE_PATHS = ("ddfbench", "conf", "pyproject.toml")  # what a result depends on (reports/, README do not count)


def code_commits(records: list[dict[str, Any]]) -> list[str]:
    """The distinct code commits of the records: env.code_sha (the last commit that changed the code), else
    env.git_sha for older records ("unknown" where a record has neither)."""
    env = [r.get("env") or {} for r in records]
    return sorted({str(e.get("code_sha") or e.get("git_sha") or "unknown") for e in env})


def _git(*args: str) -> str | None:
    """git's answer in the checkout that holds the package; None in an installed wheel (whose folder may lie inside
    another repository, whose commit is not ddfbench's) or where git fails."""
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    if not os.path.exists(os.path.join(root, ".git")):
        return None
    try:
        out = subprocess.run(["git", *args], cwd=root, capture_output=True, text=True, timeout=5)
        return out.stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None


# names the commit of a copied tree whose .git is missing or stale (a lent GPU machine's copy carries the
# working tree over the .git of the session's first commit); when set it wins over git
GIT_SHA_ENV = "DDFBENCH_GIT_SHA"


def _git_sha() -> str | None:
    return os.environ.get(GIT_SHA_ENV) or _git("rev-parse", "HEAD")


def code_sha() -> str | None:
    """The last commit that changed the code (CODE_PATHS): committing reports midway leaves it unchanged.
    $DDFBENCH_GIT_SHA where set (whoever copies the tree names a commit that changed the code)."""
    return os.environ.get(GIT_SHA_ENV) or _git("log", "-1", "--format=%H", "--", *CODE_PATHS)


OPTIONAL = ("open3d", "warp", "pymeshlab", "embreex")  # modules whose versions are recorded; a GPU machine may lack some


def _installed(module: str) -> str | None:
    """The version of the installed distribution that provides `module` (e.g. open3d-cpu for open3d); None where
    none does or where its import is blocked (sys.modules[module] is None)."""
    if module in sys.modules and sys.modules[module] is None:  # an import blocked on purpose
        return None
    from importlib import metadata

    for dist in _providers().get(module, []):
        return metadata.version(dist)
    return None


@functools.cache
def _providers() -> dict[str, list[str]]:
    """{top-level module: distributions that provide it} of this environment (one scan a process)."""
    from importlib import metadata

    return metadata.packages_distributions()


def cpu_model(cpuinfo: str = "/proc/cpuinfo") -> str | None:
    """The processor's model name as Linux names it (its first `model name` line), else None: timings are comparable
    within one model, and `cpu` holds only the architecture."""
    try:
        with open(cpuinfo, encoding="utf-8", errors="replace") as fh:
            return next((line.split(":", 1)[1].strip() for line in fh if line.startswith("model name")), None)
    except OSError:
        return None


def environment(device: str, threads: int) -> dict[str, Any]:
    """Where and with what the run was measured."""
    import numpy
    import torch
    import trimesh

    version = sys.modules[__name__.split(".")[0]].__version__  # the package, imported before any of its modules
    gpu = torch.cuda.get_device_name(0) if device.startswith("cuda") and torch.cuda.is_available() else None
    return {
        "git_sha": _git_sha(),
        "code_sha": code_sha(),
        "git_sha_from": GIT_SHA_ENV if os.environ.get(GIT_SHA_ENV) else "git",
        "versions": {"ddfbench": version, "python": platform.python_version(), "torch": torch.__version__,
                     "numpy": numpy.__version__, "trimesh": trimesh.__version__,
                     **{name: _installed(name) for name in OPTIONAL}},
        "device": device,
        "threads": int(threads),
        "cpu": platform.processor() or platform.machine(),
        "cpu_model": cpu_model(),
        "cpu_count": os.cpu_count(),
        "gpu": gpu,
        "hostname": socket.gethostname(),
    }
