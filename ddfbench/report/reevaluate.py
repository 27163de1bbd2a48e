"""python -m ddfbench.report.reevaluate RESULTS/<experiment> --out DIR [--n-points N] [--scene NAME] [--model M ...]
                                [--threads N] [--store-as float16|float32]

The finished runs of an experiment measured again at other evaluation settings, from what each run
saved: its reconstruction (reconstruction.ply) against its GT mesh (gt_mesh.ply) at N surface points
per mesh and the record's own radii and evaluation seed (metrics.eval_seed; the run's seed before 1.7.0),
and, with --scene, its saved model rendered on the CPU
with conf/scene/<NAME>.yaml (or `record`: the run's own scene) against the GT mesh's BVH (one timed render: timings are not the point; a
float16 storage level renders its rounded weights). A sweep whose probes needed a small point count
(convergence: 20k) is so compared with targets stated at the 100k points of every other experiment,
and gets image metrics it did not render, without refitting. With --store-as, each saved network (a
family with a storage_dtype: the DDF) is stored again at that dtype, which rounds it, and meshed anew at
its record's mesh_resolution: what a float16 artifact of the same fit would measure (storage_bytes
follows), and paired.md sets it against the run's saved mesh measured alike, per model and capacity
level, each run against itself (the saved mesh is the record's code's and device's: pair within one
code of the mesh extraction). The records are not changed. DIR gets
table.md (its first line: the command, the records' code commits and the measuring code's) /
table.csv (report.tables: one row per configuration, seeds pooled, empty meshes at their
penalty, the noise floor at this point count) and runs.csv (a row per run, with its swept values), all written
from the records measured again, saved beside them (ddfbench.report.measured), from which they regenerate.
A run whose artifacts cannot be read gets one line on stderr naming its folder; the others are still
written (exit 1).
"""

from __future__ import annotations

import argparse
import copy
import os
import sys
import tempfile
import zipfile
from typing import Any

import torch
import trimesh

from ddfbench.core import plugins
from ddfbench.core.errors import InputError
from ddfbench.core.geometry import BOX_HALF
from ddfbench.core.representation import Representation
from ddfbench.evaluate.metrics import geometry_metrics
from ddfbench.models import load_family
from ddfbench.report import measured, paired, tables
from ddfbench.run.checks import writable_folder
from ddfbench.run.runs import find_records

RECORD_SCENE = "record"  # --scene record: each run's own scene as its record gives it


def artifact(rec: dict[str, Any], name: str) -> str:
    """The path of the run's artifact `name`; InputError naming the run folder when it has none."""
    rel = (rec.get("artifacts") or {}).get(name)
    path = os.path.join(rec["_dir"], str(rel)) if rel else ""
    if not rel or not os.path.exists(path):
        raise InputError(f"{rec['_dir']}: no {name} artifact ({path or 'not in the record'})")
    return path


def record_evaluation_seed(rec: dict[str, Any]) -> int:
    """The evaluation seed a record's metrics were measured with: metrics.eval_seed, or the run's seed in records
    before 1.7.0 (which lack it)."""
    seed = (rec.get("metrics") or {}).get("eval_seed")
    return int(seed) if seed is not None else int((rec.get("config") or {}).get("seed", 0))


def _reconstruction(rec: dict[str, Any]) -> trimesh.Trimesh:
    """The saved reconstruction; an empty mesh where the run had none (its mesh was empty: no .ply)."""
    if not (rec.get("artifacts") or {}).get("reconstruction"):
        return trimesh.Trimesh()
    return trimesh.load(artifact(rec, "reconstruction"), force="mesh", process=False)


def saved_model(rec: dict[str, Any]) -> Representation:
    """The run's saved model, loaded for the record's field box."""
    return load_family(rec["family"]).load(artifact(rec, "model"), domain=float(rec["config"].get("domain", BOX_HALF)))


def _check_store_as(rec: dict[str, Any], dtype: str) -> None:
    """InputError naming the run folder unless its family has a storage_dtype no narrower than `dtype`
    (a float16 record stored as float32 would not measure a float32 artifact)."""
    stored = (rec["config"].get("model") or {}).get("storage_dtype")
    if stored is None:
        raise InputError(f"{rec['_dir']}: family {rec['family']} has no storage_dtype to store it as {dtype}")
    if (stored, dtype) == ("float16", "float32"):
        raise InputError(f"{rec['_dir']}: stored as float16 already; storing it as float32 cannot undo the rounding")


def _stored_as(rep: Representation, dtype: str) -> int:
    """Save `rep` again (into a temporary folder) with storage_dtype `dtype`, which rounds it as a user's
    artifact of that dtype would be; the file's bytes."""
    rep.cfg["storage_dtype"] = dtype
    with tempfile.TemporaryDirectory(prefix="ddfbench-store-") as tmp:
        rep.save(os.path.join(tmp, "model"))
        return int(rep.storage_bytes())


def _image_metrics(rec: dict[str, Any], rep: Representation, gt: trimesh.Trimesh,
                   scene: dict[str, Any]) -> dict[str, Any]:
    """The run's model `rep` rendered with `scene` against the GT mesh (render.render_scene's image metrics)."""
    from ddfbench.render import mesh_reference, render_scene  # the renderer's imports are only needed with a scene

    domain = rep.domain
    once = {**scene, "timing": {**(scene.get("timing") or {}), "repeats": 1, "warmup": 0}}
    with tempfile.TemporaryDirectory(prefix="ddfbench-reeval-") as tmp:
        seed = int(rec["config"].get("seed", 0))
        backend = str((rec["config"].get("oracle") or {}).get("backend", "open3d"))
        return render_scene(rep, mesh_reference(gt, domain, backend=backend), once, tmp, seed).get("metrics", {})


def records_parser(tool: str, description: str, out_files: str, n_points: int) -> argparse.ArgumentParser:
    """The arguments every tool that measures an experiment's finished records takes again: the records
    folder, --out, --n-points (surface points per mesh), --model and --threads."""
    ap = argparse.ArgumentParser(prog=f"python -m ddfbench.report.{tool}", description=description)
    ap.add_argument("results", help="an experiment's records folder (results/<experiment>)")
    ap.add_argument("--out", required=True, help=f"folder for {out_files}")
    ap.add_argument("--n-points", type=int, default=n_points, help=f"surface points per mesh (default {n_points})")
    ap.add_argument("--model", nargs="*", default=None, help="only these models (the records' `model` labels)")
    ap.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    return ap


def checked_counts(args: argparse.Namespace) -> None:
    """InputError unless --n-points >= 1 and --threads >= 0; sets torch's threads when --threads is given."""
    if args.n_points < 1:
        raise InputError(f"--n-points {args.n_points}: must be an integer >= 1")
    if args.threads < 0:
        raise InputError(f"--threads {args.threads}: must be an integer >= 0 (0: torch's default)")
    if args.threads:
        torch.set_num_threads(args.threads)


def finished_records(results: str, models: list[str] | None) -> list[dict[str, Any]]:
    """The ok records below `results` (of `models` only, when given); InputError when there are none."""
    recs = [r for r in find_records(results) if r.get("status") == "ok" and (not models or r.get("model") in models)]
    if not recs:
        raise InputError(f"{results}: no finished run records" + (f" of {models}" if models else ""))
    return recs


def unreadable(tool: str, rec: dict[str, Any], err: Exception) -> None:
    """One line on stderr naming the run folder whose artifacts `tool` could not measure, and why."""
    why = (str(err).splitlines() or [""])[0]
    print(f"ddfbench.report.{tool}: {rec['_dir']}: {type(err).__name__}: {why}", file=sys.stderr, flush=True)


def scene_config(name: str) -> dict[str, Any]:
    """conf/scene/<name>.yaml as a job sees it: composed by Hydra, so a preset's `defaults` (normals: depth's
    cameras) are merged in; an InputError naming the presets where there is no such file."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    plugins.plugin_yaml("scene", name)  # a missing preset: one line naming the others
    with initialize_config_dir(plugins.CONF_DIR, version_base="1.3"):
        cfg = compose("config", overrides=[f"scene={name}"])
    return OmegaConf.to_container(cfg.scene, resolve=True)


def reevaluated(rec: dict[str, Any], n_points: int, scene: dict[str, Any] | str | None,
                store_as: str | None = None) -> dict[str, Any]:
    """A copy of the record whose metrics are measured again: geometry at n_points (the record's radii,
    seed and metric switches), image metrics when the scene (a scene config, or RECORD_SCENE: the
    run's own) renders something; with store_as, of its model stored at that dtype and meshed anew."""
    cfg, ev = rec["config"], rec["config"].get("eval") or {}
    gt = trimesh.load(artifact(rec, "gt_mesh"), force="mesh", process=False)
    out = copy.deepcopy(rec)
    rep, reconstruction = None, None
    if store_as is not None:
        _check_store_as(rec, store_as)
        rep = saved_model(rec)
        out["cost"] = {**out.get("cost", {}), "storage_bytes": _stored_as(rep, store_as)}
        out["config"]["model"]["storage_dtype"] = store_as
        out["_stored_as"] = store_as
        reconstruction = rep.to_mesh(int(ev["mesh_resolution"]))
    else:
        reconstruction = _reconstruction(rec)
    out["metrics"] = geometry_metrics(gt, reconstruction, n_points, [float(r) for r in ev["radii"]],
                                      seed=record_evaluation_seed(rec), noise_floor=bool(ev.get("noise_floor", True)),
                                      with_point_to_surface=bool(ev.get("point_to_surface", True)))
    if scene == RECORD_SCENE:
        scene = dict(cfg.get("scene") or {})
    if scene is not None and scene.get("outputs"):
        out["metrics"].update(_image_metrics(rec, rep or saved_model(rec), gt, scene))
    return out


def stored_as_pairs(saved: list[dict[str, Any]], stored: list[dict[str, Any]], dtype: str) -> str:
    """paired.md: the records measured as saved against the same runs stored as `dtype` (reevaluated's
    store_as), each run against itself, per model and capacity level; chamfer L2 and F@0.01."""
    def level(rec: dict[str, Any]) -> tuple[str, str]:
        return str(rec.get("model")), str(rec["config"].get("capacity", "-"))

    def setting(rec: dict[str, Any]) -> str:
        return f"stored as {dtype}" if rec.get("_stored_as") else "as saved"

    parts = [f"# Each run's saved network stored again as {dtype}, against its saved mesh", ""]
    for model, capacity in sorted({level(r) for r in saved}):
        group = [r for r in saved + stored if level(r) == (model, capacity)]
        width = {(r["config"]["model"].get("width"), r["config"]["model"].get("depth")) for r in group}
        parts.append(f"## {model} {capacity} (width, depth {sorted(width)})\n")
        for metric in ("chamfer_l2", "fscore@0.01"):
            rows = paired.compare_settings(group, metric, setting, "as saved", pair_key=lambda r: (r["key"],))
            parts.append(paired.to_markdown(rows, metric, "as saved", "each run against itself, the same points"))
    return "\n".join(parts)


def write_tables(out: str, head: dict[str, str], rows: list[dict[str, Any]]) -> str:
    """table.md, table.csv and runs.csv of the records measured again (rows); with records stored at another dtype
    (their `_stored_as`), those are the tables' and the others, each run as saved, are paired.md's pairs. Into out;
    table.md's text."""
    stored = [r for r in rows if r.get("_stored_as")]
    done, saved = (stored, [r for r in rows if not r.get("_stored_as")]) if stored else (rows, [])
    df = tables.summarize(done)
    md = measured.first_line(head) + "\n\n" + tables.to_markdown(df)
    with open(os.path.join(out, "table.md"), "w") as fh:
        fh.write(md)
    tables.to_csv(df, os.path.join(out, "table.csv"))
    tables.per_run(done).to_csv(os.path.join(out, "runs.csv"), index=False)
    if stored:
        with open(os.path.join(out, "paired.md"), "w") as fh:
            fh.write(measured.first_line(head, "paired") + "\n\n"
                     + stored_as_pairs(saved, done, str(stored[0]["_stored_as"])))
    return md


def main(argv: list[str] | None = None) -> int:
    ap = records_parser("reevaluate", "A finished sweep measured again from its saved artifacts.",
                        "table.md, table.csv and runs.csv", 100_000)
    ap.add_argument("--scene", default=None, help="also render each saved model with conf/scene/<NAME>.yaml "
                    f"('{RECORD_SCENE}': the run's own scene)")
    ap.add_argument("--store-as", choices=("float16", "float32"), default=None,
                    help="store each saved network at this dtype (rounding it) and mesh it anew")
    args = ap.parse_args(argv)
    try:
        checked_counts(args)
        scene = scene_config(args.scene) if args.scene and args.scene != RECORD_SCENE else args.scene
        recs = finished_records(args.results, args.model)
        writable_folder(args.out, "--out ")
    except InputError as err:
        print(f"ddfbench.report.reevaluate: {err}", file=sys.stderr)
        return 2
    done, saved, failed = [], [], 0
    for i, rec in enumerate(sorted(recs, key=lambda r: (r["model"], r["shape"]["name"], r["key"]))):
        try:
            again = reevaluated(rec, args.n_points, scene, args.store_as)
            pair = reevaluated(rec, args.n_points, None) if args.store_as else None  # the saved mesh, same points
            done.append(again)
            if pair is not None:
                saved.append(pair)
        except (InputError, OSError, KeyError, ValueError, zipfile.BadZipFile) as err:
            failed += 1
            unreadable("reevaluate", rec, err)
            continue
        print(f"[{i + 1}/{len(recs)}] {rec['model']} {rec['shape']['name']} seed {rec['config'].get('seed')}: "
              f"CD-L2 {done[-1]['metrics']['chamfer_l2']:.4g}", file=sys.stderr, flush=True)
    if done:
        head = measured.header("reevaluate", argv, f"{len(done)} runs measured again ({failed} unreadable)", done,
                              args.results)
        return measured.publish("reevaluate", args.out, head, done + saved, failed)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
