"""The command line's overrides checked as words before Hydra reads them, each problem one line naming the override.

Hydra answers these in 6 to 30 lines (a parse error, the config search path, a list of options): a value it cannot
parse (`shape.path=/data/chair(1).obj`: such a value needs quotes), a config group option that has no file
(`model=ddff`, `+experiment=ablaton`; the near names are given), and a list of values without a sweep
(`model=mesh,mesh_lod500` without `-m`).
"""

from __future__ import annotations

import difflib
import os

from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.core.override_parser.types import Override, ValueType
from hydra.errors import HydraException

from ddfbench.core.errors import InputError, first_line
from ddfbench.core.plugins import CONF_DIR

MULTIRUN_FLAGS = ("-m", "--multirun", "hydra.mode=MULTIRUN")
OTHER_CONFIGS = ("-cd", "--config-dir", "-cp", "--config-path", "-cn", "--config-name")
NOT_CHOICES = ("hydra", "suite")  # folders of conf/ that a command does not choose from


def is_override(arg: str) -> bool:
    """A `key=value` word (with `+`, `++` or `~` before the key), not a flag."""
    return "=" in arg and not arg.startswith("-")


def values_of(args: list[str], key: str) -> list[str]:
    """The values the words of a command line give `key` (`key=v`, `+key=v`, `++key=v`), in their order, as written
    (not parsed); a `~key` deletion gives none."""
    return [a.split("=", 1)[1] for a in args if a.lstrip("+").startswith(f"{key}=")]


def parsed(arg: str) -> Override:
    """The override as Hydra reads it; a one-line InputError where it cannot."""
    try:
        (override,) = OverridesParser.create().parse_overrides([arg])
    except HydraException as exc:
        key, _, value = arg.partition("=")
        raise InputError(f"{arg}: Hydra cannot read this value ({first_line(exc)}); a value with ( ) [ ] {{ }} , = ' "
                         f"\" or spaces needs quotes: \"{key}='{value}'\"") from None
    return override


def group_options(group: str) -> list[str]:
    """The options of a config group: the YAML files of conf/<group>/, by name."""
    folder = os.path.join(CONF_DIR, group)
    return sorted(f[:-5] for f in os.listdir(folder) if f.endswith(".yaml"))


def check_choice(arg: str, group: str, value: object) -> None:
    """A one-line InputError when `value` is not an option of the config group, with the near ones."""
    options = group_options(group)
    if not isinstance(value, str) or value in options:
        return
    near = difflib.get_close_matches(value, options, n=3, cutoff=0.6)
    hint = f"did you mean {', '.join(near)}? " if near else ""
    if group == "shape" and looks_like_a_file(value):
        hint = f"a mesh file is read with shape=file shape.path={value}; "
    raise InputError(f"{arg}: no {group} named {value!r} ({hint}{group} options: {', '.join(options)})")


def looks_like_a_file(value: str) -> bool:
    """Whether a value given where a catalog name goes (`shape=/data/chair.obj`) reads as a file: a folder in it or
    a mesh file's extension."""
    from ddfbench.truth.shapes import MESH_EXTENSIONS

    ext = value.rsplit(".", 1)[-1].lower() if "." in value else ""  # `shape=obj` names no file
    return "/" in value or os.sep in value or ext in MESH_EXTENSIONS


def other_configs(args: list[str]) -> bool:
    """Whether the command adds or swaps config folders (-cd, -cp, -cn, hydra.searchpath): their options are Hydra's
    to check."""
    return any(a in OTHER_CONFIGS or a.startswith(tuple(f"{f}=" for f in OTHER_CONFIGS) + ("hydra.searchpath",))
               for a in args)


def check_overrides(args: list[str], sweeps: bool) -> None:
    """Every override of args readable, every config group choice an existing option of conf/ (unless the command
    adds config folders), and a list of values only where the command sweeps (sweeps: -m, an experiment, or the
    default run, which is one). A glob, range or interpolation among the values is left to Hydra."""
    groups = {g for g in os.listdir(CONF_DIR) if os.path.isdir(os.path.join(CONF_DIR, g)) and g not in NOT_CHOICES}
    own_configs = not other_configs(args)
    for arg in (a for a in args if is_override(a)):
        override = parsed(arg)
        key = override.get_key_element().lstrip("+~")
        if override.is_sweep_override() and not sweeps:
            raise InputError(f"{arg}: a list of values is a sweep: add -m to run one job per value")
        if key not in groups or arg.startswith("~") or not own_configs:
            continue
        if not override.is_sweep_override():
            values = [override.value()]
        elif override.value_type in (ValueType.CHOICE_SWEEP, ValueType.SIMPLE_CHOICE_SWEEP):
            values = list(override.sweep_string_iterator())
        else:  # a glob (Hydra expands it against the options itself), a range or an interval
            values = []
        for value in values:
            if not (isinstance(value, str) and "$" in value):  # an interpolation: resolved when the job composes
                check_choice(arg, key, value)


def check_shape_path(args: list[str]) -> None:
    """A `shape.path` on a command line whose shapes are catalog shapes, which ignore it, so that the file would
    silently not be read: no `shape=` or `shape.name=` (the bunny, or an experiment's shapes) or only catalog names
    (`shape=bunny shape.path=...`; a list that names `file` reads it)."""
    paths = values_of(args, "shape.path")
    chosen = [*values_of(args, "shape"), *values_of(args, "shape.name")]
    if not paths or other_configs(args) or any("$" in v for v in chosen):
        return
    names = {n.strip(" []") for v in chosen for n in v.split(",")}
    if not chosen:
        raise InputError(f"shape.path={paths[-1]}: a path is read only with shape=file (without it the run's shapes "
                         f"are catalog shapes, which ignore it): add shape=file")
    if "file" not in names:
        raise InputError(f"shape.path={paths[-1]}: shape={chosen[-1]} is a catalog shape, which ignores a path: "
                         f"use shape=file")
