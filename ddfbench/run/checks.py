"""A job's config checked before any work: keys known, numbers finite and in range, path-forming names safe, the
model's and the scene's sections against their YAML.

Each problem is one InputError line naming the key, the value and what is allowed. The families, samplers and
scenes check their own sections against their YAML (ddfbench.core.plugins, ddfbench.sampling.params,
ddfbench.render.scene); this module checks the rest of the job: the top level, `train`, `eval` and `oracle`.
"""

from __future__ import annotations

import functools
import math
import numbers
import os
import re
from typing import Any, Callable, Mapping

from ddfbench.core import plugins
from ddfbench.core.errors import InputError, checked_int
from ddfbench.fit.budget import KINDS
from ddfbench.models import load_family
from ddfbench.render.scene import parse_scene

# One path component: a letter or digit first, then letters, digits, '_', '-', '.'; at most 100 characters.
# Leading dots (., .., .cache, .hydra: the folders ddfbench keeps in out_dir) and separators are refused.
SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,99}")
CHECKED_SECTIONS = ("train", "eval", "oracle")  # the sections of the job config this module owns
GROUPS = ("shape", "sampling", "model", "train", "scene", "eval", "tracking")  # conf/config.yaml's defaults


def safe_name(value: Any, key: str) -> str:
    """value as one safe path component (SAFE_NAME), else a one-line InputError naming key."""
    if not isinstance(value, str) or not SAFE_NAME.fullmatch(value) or ".." in value:
        raise InputError(f"{key}={value!r}: must be one folder name (letters, digits, '_', '-', '.'; a letter or digit "
                         "first; no '..', '/' or leading dot; at most 100 characters)")
    return value


def writable_folder(path: str, named: str) -> None:
    """Make the folder `path` if it is missing; a one-line InputError (`named` + path first) where it cannot be made
    or written."""
    if not path:
        raise InputError(f"{named}'': must name a folder")
    if os.path.exists(path) and not os.path.isdir(path):
        raise InputError(f"{named}{path}: exists and is not a folder")
    try:
        os.makedirs(path, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{named}{path}: cannot be made ({exc.strerror or exc})") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise InputError(f"{named}{path}: cannot be written")


def check_conf_found() -> None:
    """ddfbench reads its Hydra configs from the package's conf/ (a checkout links it to its top-level conf/, a wheel
    carries it); a one-line InputError where they are missing (a copy of the package alone, a broken install)."""
    if os.path.isfile(plugins.CONF_DIR):  # the link checked out as a text file
        raise InputError(f"{plugins.CONF_DIR}: a file, not the link to conf/: this checkout was made without "
                         "symlinks (git config core.symlinks true, then git checkout -- ddfbench/conf)")
    if not os.path.isfile(os.path.join(plugins.CONF_DIR, "config.yaml")):
        raise InputError(f"{plugins.CONF_DIR}: no configs there: install ddfbench with them (pip install . from a "
                         "checkout, whose ddfbench/conf links its conf/)")


@functools.lru_cache(maxsize=None)
def declared_values() -> dict[str, dict[str, tuple[Any, ...]]]:
    """{"": top-level keys, "train" / "eval" / "oracle": their keys} -> every value a YAML gives the key: what
    conf/config.yaml, the train and eval groups and the experiments (which may add keys of their own, such as
    `capacity`) declare."""
    out: dict[str, dict[str, list[Any]]] = {"": {g: [] for g in GROUPS}, "oracle": {}}

    def declare(section: str, values: Mapping[str, Any]) -> None:
        for key, value in values.items():
            out.setdefault(section, {}).setdefault(key, []).append(value)

    config = plugins.top_yaml()
    declare("", config)
    declare("oracle", config["oracle"])
    for section in ("train", "eval"):
        for name in plugins.names(section):
            declare(section, plugins.plugin_yaml(section, name))
    for name in plugins.names("experiment"):
        experiment = plugins.plugin_yaml("experiment", name)
        declare("", experiment)
        for section in CHECKED_SECTIONS:
            if isinstance(experiment.get(section), dict):
                declare(section, experiment[section])
    out[""].pop("defaults", None)
    return {section: {k: tuple(v) for k, v in keys.items()} for section, keys in out.items()}


def declared_keys() -> dict[str, frozenset[str]]:
    """{"": top-level keys, "train" / "eval" / "oracle": their keys} (declared_values)."""
    return {section: frozenset(keys) for section, keys in declared_values().items()}


def check_flags(cfg: Mapping[str, Any]) -> None:
    """A key every YAML gives true or false (force, quiet, eval.noise_floor, ...) holds true or false."""
    for section, keys in declared_values().items():
        for key, values in keys.items():
            if values and all(isinstance(v, bool) for v in values):
                value = cfg.get(key) if not section else (cfg.get(section) or {}).get(key)
                if not isinstance(value, bool):
                    raise InputError(f"{section + '.' if section else ''}{key}={value!r}: must be true or false")


def check_known_keys(cfg: Mapping[str, Any]) -> None:
    """A `+key=` that nothing reads (at the top level, or in train, eval, oracle) is a one-line InputError that
    lists the near-miss names."""
    known = declared_keys()
    plugins.strict_keys("", {k: v for k, v in cfg.items() if k != "hydra"}, dict.fromkeys(known[""]), near=True)
    for section in CHECKED_SECTIONS:
        value = cfg.get(section)
        if not isinstance(value, Mapping):
            raise InputError(f"{section}={value!r}: must be a mapping with keys {', '.join(sorted(known[section]))}")
        plugins.strict_keys(section, value, dict.fromkeys(known[section]), near=True)


def _number(value: Any, key: str, ok: Callable[[float], bool], allowed: str) -> float:
    """value as a finite float for which ok holds, else a one-line InputError naming key and what is allowed."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value) or not ok(value):
        raise InputError(f"{key}={value!r}: must be {allowed}")
    return float(value)


def _get(cfg: Mapping[str, Any], dotted: str) -> Any:
    section, _, key = dotted.partition(".")
    return cfg[section][key] if key else cfg[section]


# (key, least integer) for whole-number settings; a None value is allowed where the key is in NULLABLE
INTEGERS = (("seed", 0), ("threads", 0), ("train.max_steps", 1), ("train.n_labels", 1), ("train.n_probes", 0), ("train.probe_points", 1),
            ("train.probe_resolution", 2), ("eval.n_points", 1), ("eval.mesh_resolution", 2),
            ("oracle.occupancy_rays", 1))
NULLABLE = ("threads", "train.max_steps", "train.max_epochs", "train.n_labels")
SEED_LIMIT = 2**63  # seeds in [0, 2**63): int64 in tables; with the offsets the stages add (up to +11) numpy's and
# torch's generators still take them (they refuse 2**64 and above)
BYTES_A_POINT = 600  # peak memory of the geometry metrics per sampled point (534 B measured at 10^6 on the bunny)
POINT_COUNTS = ("eval.n_points", "train.probe_points")


def physical_memory() -> int:
    """This machine's memory in bytes."""
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def check_numbers(cfg: Mapping[str, Any]) -> None:
    """Every numeric setting of the job finite and in range (see INTEGERS and the rules below)."""
    _number(cfg["domain"], "domain", lambda x: x > 0.5, "a finite number > 0.5 (the field box holds the unit cube)")
    for key, least in INTEGERS:
        value = _get(cfg, key)
        if not (value is None and key in NULLABLE):
            checked_int(value, key, least)
    if cfg["seed"] >= SEED_LIMIT:
        raise InputError(f"seed={cfg['seed']}: must be an integer >= 0 and < 2**63")
    for key in POINT_COUNTS:
        need, have = _get(cfg, key) * BYTES_A_POINT, physical_memory()
        if need > have:
            raise InputError(f"{key}={_get(cfg, key)}: needs about {BYTES_A_POINT} bytes a point "
                             f"({need / 1e9:.3g} GB), more than this machine's {have / 1e9:.3g} GB of memory")
    if cfg["train"]["max_epochs"] is not None:
        _number(cfg["train"]["max_epochs"], "train.max_epochs", lambda x: x > 0, "a finite number > 0 or null")
    _number(cfg["train"]["max_seconds"], "train.max_seconds", lambda x: x > 0, "a finite number of seconds > 0")
    if cfg["train"]["budget"] not in KINDS:
        raise InputError(f"train.budget={cfg['train']['budget']!r}: must be one of {', '.join(KINDS)}")
    if cfg["train"]["budget"] == "epochs" and cfg["train"]["max_epochs"] is None:
        raise InputError("train.budget='epochs': needs train.max_epochs, a number of epochs > 0 (it is null)")
    if cfg.get("checkpoint_every") is not None:
        _number(cfg["checkpoint_every"], "checkpoint_every", lambda x: x >= 0, "a finite number of seconds >= 0 "
                "(0: no checkpoints)")
    radii = cfg["eval"]["radii"]
    if not isinstance(radii, (list, tuple)) or not radii:
        raise InputError(f"eval.radii={radii!r}: must be a list of distances > 0")
    for i, radius in enumerate(radii):
        _number(radius, f"eval.radii[{i}]", lambda x: x > 0, "a finite distance > 0")
    model = cfg["model"]
    for key in ("lr", "lr_d"):
        if key in model:
            _number(model[key], f"model.{key}", lambda x: x > 0, "a finite learning rate > 0")
    if "faces" in model:
        checked_int(model["faces"] or 0, "model.faces", 0)


def check_shape_file(cfg: Mapping[str, Any]) -> None:
    """shape=file names its shape by its file: a `shape.name` beside it that the catalog lacks was meant as the
    file's name (a catalog shape ignores a `shape.path` a sweep sets for all its shapes)."""
    from ddfbench.truth.shapes import catalog

    shape = cfg.get("shape") or {}
    name = str(shape.get("name"))
    if shape.get("path") and name != "file" and name not in catalog() and not name.startswith("hard/"):
        stem = os.path.splitext(os.path.basename(str(shape.get("path") or "")))[0] or "the file's name"
        raise InputError(f"shape.name={shape.get('name')!r}: with shape=file the shape takes its file's name ({stem}); "
                         "drop shape.name")


def check_modules_named(cfg: Mapping[str, Any]) -> None:
    """The model's YAML names its family, and, for a family that trains on samples, the sampler's its strategy: the
    modules that build them."""
    needs = [("model", "family", "ddfbench/models")]
    family = (cfg.get("model") or {}).get("family")
    if family is not None and load_family(str(family)).sample_kind is not None:
        needs.append(("sampling", "strategy", "ddfbench/sampling"))
    for section, key, where in needs:
        if (cfg.get(section) or {}).get(key) is None:
            raise InputError(f"{section}.{key}: not set: the {section} YAML names the module that builds it "
                             f"({key}: <a module of {where}>)")


def check_job(cfg: Mapping[str, Any]) -> None:
    """Every check of this module, in the order a user would fix them: names, keys, numbers; then the model's
    keys and types against its YAML (Representation.configure; a family may check more of its values there, the
    DDF does) and the scene's keys and values (render.scene.parse_scene), so that none waits for the fit."""
    safe_name(cfg.get("experiment_name", "single"), "experiment_name")
    check_known_keys(cfg)
    check_modules_named(cfg)
    check_shape_file(cfg)
    check_flags(cfg)
    check_numbers(cfg)
    load_family(str(cfg["model"]["family"])).configure(cfg["model"])
    if (cfg.get("scene") or {}).get("outputs"):
        parse_scene(cfg["scene"])
