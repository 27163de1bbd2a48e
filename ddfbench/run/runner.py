"""One job, stage by stage: shape → oracle → samples → fit → extract → metrics → render → record.

`run(cfg)` never raises for a bad input or a failing stage: it writes a `failed` record with a
one-line error (traceback beside it in error.log) and returns it; the CLI turns that into a
non-zero exit for a single run, while a sweep goes on.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import logging
import os
import time
import traceback
from typing import Any, Mapping

import numpy as np
import torch
from filelock import FileLock

from ddfbench.core import heap, plugins
from ddfbench.core.atomic import write_atomic
from ddfbench.core.errors import InputError, checked_int, first_line, one_line
from ddfbench.core.geometry import BOX_HALF
from ddfbench.core.representation import Budget, FitData, Representation
from ddfbench.evaluate.metrics import cloud_metrics, evaluation_seed, geometry_metrics, penalty_metrics, sample_surface
from ddfbench.fit.budget import fit_limit, fit_record
from ddfbench.fit.checkpoint import FILE as CHECKPOINT_FILE
from ddfbench.fit.checkpoint import Checkpoint, code_fingerprint
from ddfbench.fit.train import resolve_device, seed_everything, strict_fp32
from ddfbench.models import load_family
from ddfbench.run import checks, runs
from ddfbench.run.tracking import track_record
from ddfbench.truth.oracle import Oracle
from ddfbench.truth.shapes import load_shape

log = logging.getLogger(__name__)
ERROR_LOG = "error.log"  # in a failed run's folder: the traceback of its failure


class StageFailed(RuntimeError):
    """A stage ended without an exception but with a failure it reported (e.g. the NaN guard)."""


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def _probe_fn(gt_points: np.ndarray, resolution: int, radii: list[float]):
    """Cheap accuracy probe for fit curves: chamfer L2 and f-score on len(gt_points) samples."""

    def probe(rep: Representation) -> dict[str, float]:
        mesh = rep.to_mesh(resolution)
        if len(mesh.faces) == 0 or mesh.area <= 0:
            m = penalty_metrics(radii)
        else:
            m = cloud_metrics(gt_points, sample_surface(mesh, len(gt_points), 1)[0], radii)
        return {"chamfer_l2": m["chamfer_l2"], **{f"fscore@{r}": v for r, v in m["fscore"].items()}}

    return probe


def _set_threads(threads: int) -> int:
    n = int(threads) if threads and threads > 0 else (os.cpu_count() or 1)
    torch.set_num_threads(n)
    return n


def _stages(cfg: Mapping[str, Any], rdir: str, device: str, seed: int, out: dict[str, Any]) -> None:
    """Run every stage, filling `out` (the record in progress) as each finishes."""
    from ddfbench import sampling

    cost, artifacts = out["cost"], out["artifacts"]
    ev, tr = cfg["eval"], cfg["train"]
    n_points = int(ev["n_points"])  # checked with every setting before any work (ddfbench.run.checks)
    shape = load_shape(cfg["shape"])
    out["shape"] = shape.summary()
    oracle = Oracle(shape.mesh, **cfg.get("oracle", {}))
    Family = load_family(str(cfg["model"]["family"]))
    if Family.needs_closed_surface and not shape.watertight:
        out["flags"].append("non_watertight_input")
    os.makedirs(rdir, exist_ok=True)
    shape.mesh.export(os.path.join(rdir, "gt_mesh.ply"), file_type="ply", encoding="binary")
    artifacts["gt_mesh"] = "gt_mesh.ply"

    samples, info = None, {}
    if Family.sample_kind is None:  # the family builds from the mesh: no samples, no sampling time or count
        out["sampling"] = {"strategy": None, "kind": None}  # (the sampler's unused config stays in record.config)
    else:
        cache_dir = os.path.join(cfg.get("out_dir", "results"), ".cache", "datasets")
        samples, dataset_path, info = sampling.build(shape, oracle, dict(cfg["sampling"]), Family.sample_kind, seed,
                                                     cache_dir)
        if cfg["train"].get("n_labels"):  # matched label counts: a seeded subset of what the strategy produced
            want = int(cfg["train"]["n_labels"])
            if want > len(samples):
                raise InputError(f"train.n_labels={want}: sampling={cfg['sampling']['strategy']} gave only "
                                 f"{len(samples)} labels on {shape.name} (raise its sample size or lower n_labels)")
            info = dict(info, n_generated=len(samples), n_samples=want)
            samples = samples.subset(want, np.random.default_rng(seed + 11))
        out["sampling"] = {**dict(cfg["sampling"]), **info}
        cost["sampling_s"] = float(info.get("sampling_s", 0.0))
        artifacts["dataset"] = os.path.relpath(dataset_path, rdir)

    radii = [float(r) for r in ev["radii"]]
    domain = float(cfg.get("domain", BOX_HALF))
    rep = Family(dict(cfg["model"]), domain=domain)
    n_labels = info.get("n_samples")
    limit = fit_limit(tr, rep.cfg, n_labels)  # rep.cfg: the preset over its family's defaults (batch, visibility)
    every = float(cfg.get("checkpoint_every", 0) or 0)
    budget = Budget(max_steps=limit.max_steps, max_seconds=limit.max_seconds, device=device,
                    seed=seed, n_probes=int(tr.get("n_probes", 5)),
                    checkpoint=Checkpoint(os.path.join(rdir, CHECKPOINT_FILE), every, code_fingerprint()) if every > 0 else None)
    gt_probe_points = sample_surface(shape.mesh, int(tr.get("probe_points", 5000)), seed + 7)[0]
    probe_res = min(int(tr.get("probe_resolution", 48)), int(ev["mesh_resolution"]))
    probe = _probe_fn(gt_probe_points, probe_res, radii)
    t0 = time.perf_counter()
    stats = rep.fit(FitData(samples=samples, mesh=shape.mesh, oracle=oracle), budget, probe)
    cost["fit_wall_s"] = time.perf_counter() - t0
    cost["fit_s"] = float(stats.seconds)
    out["fit"] = {"steps": stats.steps, "seconds": stats.seconds, "loss_curve": stats.loss_curve,
                  "probes": stats.probes, "status": stats.status, "message": stats.message, **stats.extra,
                  **fit_record(limit, stats.extra.get("stop"), stats.steps, rep.cfg, n_labels,
                             stats.extra.get("entry_per_batch"))}
    if stats.status != "ok":
        raise StageFailed(f"fit of {Family.family} failed: {stats.message}")

    saved = rep.save(os.path.join(rdir, "model"))  # first: a lossy storage dtype rounds what is measured below
    artifacts["model"] = os.path.relpath(saved, rdir)
    cost["storage_bytes"] = int(rep.storage_bytes())
    cost["n_params"] = int(rep.n_params())

    t0 = time.perf_counter()
    rec = rep.to_mesh(int(ev["mesh_resolution"]))
    cost["extract_s"] = time.perf_counter() - t0
    if rep.extract_info.get("field_evals") is not None:
        cost["extract_field_evals"] = int(rep.extract_info["field_evals"])
    if rep.extract_info.get("capped"):
        out["flags"].append("extraction_capped")
    if len(rec.faces):
        write_atomic(os.path.join(rdir, "reconstruction.ply"),
                     lambda fh: rec.export(fh, file_type="ply", encoding="binary"), "wb")
        artifacts["reconstruction"] = "reconstruction.ply"

    t0 = time.perf_counter()
    out["metrics"] = geometry_metrics(shape.mesh, rec, n_points, radii, seed=evaluation_seed(seed),
                                      noise_floor=bool(ev.get("noise_floor", True)),
                                      with_point_to_surface=bool(ev.get("point_to_surface", True)))
    cost["metrics_s"] = time.perf_counter() - t0
    if out["metrics"].get("empty_reconstruction"):
        out["flags"].append("empty_reconstruction")

    scene = dict(cfg.get("scene") or {})
    if scene.get("outputs"):
        from ddfbench.render import mesh_reference, render_scene

        reference = mesh_reference(shape.mesh, domain, device, str(cfg.get("oracle", {}).get("backend", "open3d")))
        result = render_scene(rep, reference, scene, rdir, seed)
        out["metrics"].update(result.get("metrics", {}))
        cost.update(result.get("cost", {}))
        out["counts"].update(result.get("counts", {}))
        artifacts["renders"] = result.get("artifacts")


def _record_error(exc: BaseException) -> str:
    """The record's `error`: the message alone where it is ours and names what is wrong (InputError,
    StageFailed), else errors.one_line (its type first); the traceback goes to error.log."""
    return first_line(exc) if isinstance(exc, (InputError, StageFailed)) else one_line(exc)


def run(cfg: Mapping[str, Any], choices: Mapping[str, str] | None = None,
        overrides: list[str] | None = None, device: str | None = None) -> dict[str, Any]:
    """Run one job from a resolved config (plain dict); return its record (also written to disk).

    The levels the config asks for (capacity, sample_size) are applied first (plugins.job_config), so
    the record key and the record's config are those of the job as it runs. One process at a time runs a
    key (a lock file in its run folder): a second launch of the same key waits, then finds the first's record.
    An experiment_name that is not one safe folder name, or a force that is not true or false, raises InputError
    (no record can be placed, or an earlier one would be lost); a run
    folder or record that cannot be written (a full disk, out_dir a file) gives a failed record that is
    returned, not written.

    choices: Hydra's config-group choices (the record's `model` label); device: the job's device as
    the launcher gives it (ddfbench.run.launch.job_device); None means train.device.
    """
    choices = dict(choices or {})
    try:
        cfg, bad_level = plugins.job_config(cfg, choices), None
    except InputError as exc:  # a level the model or sampler lacks: a failed record, keyed on the config as asked
        asked = {k: cfg.get(k) for k in plugins.LEVEL_KEYS.values()}
        cfg, bad_level = {**plugins.job_config({**cfg, **dict.fromkeys(asked)}), **asked}, exc
    experiment = checks.safe_name(cfg.get("experiment_name", "single"), "experiment_name")
    if not isinstance(cfg.get("force", False), bool):  # before an earlier run's record or checkpoint is touched
        raise InputError(f"force={cfg.get('force')!r}: must be true or false")
    out_dir = str(cfg.get("out_dir", "results"))
    key = runs.config_key(cfg)
    rdir = runs.run_dir(out_dir, experiment, key)
    rpath = os.path.join(rdir, runs.RECORD_FILE)
    if runs.is_done(rpath) and not cfg.get("force", False):  # done: read without the lock (a read-only out_dir)
        return _done(cfg, rpath, rdir)
    try:
        os.makedirs(rdir, exist_ok=True)
        with FileLock(os.path.join(rdir, runs.LOCK_FILE)):
            return _run_locked(cfg, choices, overrides, device, bad_level, experiment, key, rdir)
    except OSError as exc:  # nothing of this run could be kept: say so in one line, let a sweep go on
        record = _new_record(cfg, choices, overrides, experiment, key)
        record["error"] = f"out_dir={out_dir}: the run's files cannot be written ({one_line(exc)})"
        log.error("run %s failed: %s", key, record["error"])
        return record


def _done(cfg: Mapping[str, Any], rpath: str, rdir: str) -> dict[str, Any]:
    """The ok record of a finished key (mirrored to tracking if it is not yet)."""
    log.debug("skip %s: ok record exists (force=true re-runs)", rpath)
    record = runs.read_record(rpath)
    track_record(cfg.get("tracking"), str(cfg.get("out_dir", "results")), record, rdir)  # no-op if logged
    return record


def _new_record(cfg: Mapping[str, Any], choices: Mapping[str, str], overrides: list[str] | None, experiment: str,
                key: str) -> dict[str, Any]:
    """A `failed` record of the job with every field of runs.RECORD_FIELDS, to be filled as its stages finish."""
    scene = dict(cfg.get("scene") or {})
    return {
        "schema_version": runs.SCHEMA_VERSION, "key": key, "status": "failed", "error": None,
        "experiment": experiment, "family": str(cfg.get("model", {}).get("family")),
        "model": choices.get("model", str(cfg.get("model", {}).get("family"))),
        "shape": {"name": cfg.get("shape", {}).get("name")}, "sampling": dict(cfg.get("sampling") or {}),
        "scene": {k: scene.get(k) for k in ("name", "outputs", "width", "height", "spp", "max_depth")},
        "metrics": {}, "cost": {}, "counts": {}, "artifacts": {}, "flags": [],
        "config": {**runs.semantic_config(cfg), **({"inputs": digests} if (digests := runs.input_digests(cfg)) else {})},
        "overrides": list(overrides or []), "env": {},
        "started": _now(), "finished": None,
    }


def _remove(path: str) -> None:
    """Delete the file at path if there is one."""
    with contextlib.suppress(FileNotFoundError):
        os.remove(path)


def _run_locked(cfg: Mapping[str, Any], choices: Mapping[str, str], overrides: list[str] | None, device: str | None,
                bad_level: InputError | None, experiment: str, key: str, rdir: str) -> dict[str, Any]:
    """run() once it holds the key's lock: skip a key another process finished meanwhile, else run every stage
    and write the record."""
    rpath = os.path.join(rdir, runs.RECORD_FILE)
    if runs.is_done(rpath) and not cfg.get("force", False):
        return _done(cfg, rpath, rdir)

    heap_kept = heap.keep_freed_blocks()  # CPU fits reuse their multi-MB activations (ddfbench.core.heap)
    out = _new_record(cfg, choices, overrides, experiment, key)
    try:
        # a forced rerun starts its fit over, and its old record goes first: a run killed midway leaves no record
        # beside the new artifacts that would vouch for them; an earlier attempt's error log goes too
        if cfg.get("force", False):
            Checkpoint(os.path.join(rdir, CHECKPOINT_FILE)).remove()
            _remove(rpath)
        _remove(os.path.join(rdir, ERROR_LOG))
        threads = _set_threads(checked_int(cfg.get("threads") or 0, "threads", 0))
        device = resolve_device(device or str(cfg.get("train", {}).get("device", "cpu")))
        if device.startswith("cuda"):
            strict_fp32()  # a CUDA record computes in float32, as a CPU one
        out["env"] = {**runs.environment(device, threads), "glibc_heap_kept": heap_kept}
        if bad_level is not None:
            raise bad_level
        checks.check_job(cfg)  # every setting, before any work
        seed = checked_int(cfg.get("seed", 0), "seed", 0)
        seed_everything(seed)  # a reused worker process starts each run from the same state
        _stages(cfg, rdir, device, seed, out)
        out["status"] = "ok"
    except Exception as exc:  # every failure becomes a record, never a crash mid-sweep
        out["error"] = _record_error(exc)
        try:
            with open(os.path.join(rdir, ERROR_LOG), "w") as fh:
                fh.write(traceback.format_exc())
        except OSError:  # a full disk: the record below says what failed, or run() reports that it cannot
            pass
        log.debug("run %s failed: %s", key, out["error"])  # said once: by the CLI (a run) or the progress line (a sweep)
    out["finished"] = _now()
    runs.write_json_atomic(rpath, out)
    if out["status"] == "ok":  # the record holds the fit now. A failed record (rerun by the next sweep) and
        try:                    # a killed process keep it: the rerun resumes
            Checkpoint(os.path.join(rdir, CHECKPOINT_FILE)).remove()
        except OSError as exc:  # the ok record stands; the stale checkpoint is only disk space
            log.warning("run %s: its fit checkpoint could not be removed (%s)", key, one_line(exc))
    elif os.path.exists(os.path.join(rdir, CHECKPOINT_FILE)):
        log.info("run %s keeps its fit checkpoint: a rerun by the same code resumes it (force=true fits anew)", key)
    track_record(cfg.get("tracking"), str(cfg.get("out_dir", "results")), out, rdir)
    return out
