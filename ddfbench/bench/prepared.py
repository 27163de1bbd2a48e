"""Prepared inputs of a bench section: trained networks, built grids and mesh LODs, made once and reused.

With the sizes key `prepared` set to a folder, `artifact` loads what an earlier process (or another machine)
saved there and makes and saves what is missing. So repeated runs of a section in fresh processes (issue 51:
the race in five processes with five ray seeds) time the same networks on new rays, a fit is fixed work done
once rather than wall-clock work done per run, and a GPU machine without pymeshlab gets LODs made elsewhere.
A file is named by what it holds and a hash of what made it (preset config and fit budget), so a changed
preset or budget makes a new file instead of reading a stale one; the code that made it is not in the hash, so
a change to a family's code reuses the old files (start a new folder). Without the key, everything is made in the
process and nothing is written.
"""

from __future__ import annotations

import hashlib
import json
import os
from typing import Any, Callable, TypeVar

import numpy as np
import trimesh

from ddfbench.core.atomic import write_atomic
from ddfbench.core.errors import InputError
from ddfbench.core.representation import Representation

R = TypeVar("R", bound=Representation)


def file_stem(folder: str, name: str, spec: dict[str, Any]) -> str:
    """folder/<name>-<10 hex digits of spec's JSON> (spec: what made the artifact; keys sorted)."""
    digest = hashlib.sha1(json.dumps(spec, sort_keys=True, default=str).encode()).hexdigest()[:10]
    return os.path.join(folder, f"{name}-{digest}")


def _folder(sizes: dict) -> str | None:
    folder = sizes.get("prepared")
    if folder and not os.path.isdir(folder):
        os.makedirs(folder, exist_ok=True)
    return folder or None


def artifact(sizes: dict, name: str, spec: dict[str, Any], family: type[R],
             make: Callable[[], tuple[R, dict]]) -> tuple[R, dict]:
    """(rep, info): loaded from sizes' `prepared` folder when an artifact of `name` made by `spec` is there
    (info as saved, with "prepared": its file's name), else make() -> (rep, info), saved there when the key is set
    (info then names the file it was saved as, the same "prepared").
    family: the Representation class whose load reads the file."""
    folder = _folder(sizes)
    if folder is None:
        return make()
    stem = file_stem(folder, name, spec)
    if os.path.exists(f"{stem}.json"):
        with open(f"{stem}.json") as fh:
            saved = json.load(fh)
        try:
            rep = family.load(saved["path"] if os.path.isabs(saved["path"]) else os.path.join(folder, saved["path"]))
        except (OSError, KeyError) as exc:
            raise InputError(f"prepared artifact {stem}.json: its file is unreadable ({exc})") from None
        return rep, {**saved["info"], "prepared": os.path.basename(stem)}
    rep, info = make()
    path = rep.save(stem)
    _write_json(f"{stem}.json", {"path": os.path.basename(path), "spec": spec, "info": info})
    # named as a later process that loads it names it: the process that made it raced the same network, and
    # bench.repeats pools runs only where every run names the same one
    return rep, {**info, "prepared": os.path.basename(stem)}


def mesh(sizes: dict, name: str, spec: dict[str, Any], make: Callable[[], trimesh.Trimesh]) -> trimesh.Trimesh:
    """A mesh (a LOD, a subdivision) from sizes' `prepared` folder (<name>-<hash>.npz: vertices (V, 3) float64,
    faces (F, 3) int64), else make(), saved there when the key is set."""
    folder = _folder(sizes)
    if folder is None:
        return make()
    path = f"{file_stem(folder, name, spec)}.npz"
    if os.path.exists(path):
        with np.load(path) as z:
            return trimesh.Trimesh(z["vertices"], z["faces"], process=False)
    out = make()
    write_atomic(path, lambda fh: np.savez(fh, vertices=np.asarray(out.vertices, np.float64),
                                           faces=np.asarray(out.faces, np.int64)), "wb")
    return out


def _write_json(path: str, doc: dict) -> None:
    """Written whole or not at all (a stopped process leaves no half file that a later one would trust)."""
    write_atomic(path, lambda fh: json.dump(doc, fh, indent=1, default=str))
