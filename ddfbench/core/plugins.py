"""The registry of plugins: families (conf/model/) and samplers (conf/sampling/), read from their YAML.

A plugin is one module plus one YAML, conf/<group>/<name>.yaml. The YAML is the one source of the
plugin's defaults (a preset such as ddf_paper names its family and overrides some of them). Besides its
config it may carry `experiments`: the experiments the plugin joins and, per experiment, its levels,
each a partial config merged onto the job's config when the experiment sets the group's level key
(`capacity` for a model, `sample_size` for a sampler); `{levels_of: <other>}` in place of a level table
takes the levels that config <other> of the group declares for the experiment, so two presets of one
family share one table. Experiments name their sweep lists as
`${members:model,pareto}`, so "every family" is every YAML that joins, and nothing else keeps a list.
"""

from __future__ import annotations

import copy
import difflib
import functools
import os
from typing import Any, Mapping

from omegaconf import OmegaConf

from ddfbench.core.errors import InputError

# Hydra configs: the package's conf/, in a checkout a link to conf/ at the top of the repository (a wheel carries
# them as files there)
CONF_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "conf")

META_KEY = "experiments"  # the part of a plugin's YAML that is about experiments, not its config
LEVEL_KEYS = {"model": "capacity", "sampling": "sample_size"}  # group -> the job key that picks a level
NAME_KEYS = {"model": "family", "sampling": "strategy"}  # group -> the key naming the implementing module
LEVELS_OF = "levels_of"  # experiments.<experiment>: {levels_of: <config>}: that config's levels there


@functools.lru_cache(maxsize=None)
def _load(path: str) -> dict[str, Any]:
    return OmegaConf.to_container(OmegaConf.load(path), resolve=False)  # type: ignore[return-value]


def plugin_yaml(group: str, name: str) -> dict[str, Any]:
    """conf/<group>/<name>.yaml as a plain dict (interpolations kept); InputError when there is none."""
    path = os.path.join(CONF_DIR, group, f"{name}.yaml")
    if not os.path.isfile(path):
        raise InputError(f"{group}={name}: no conf/{group}/{name}.yaml (available: {', '.join(names(group))})")
    return copy.deepcopy(_load(path))


def top_yaml() -> dict[str, Any]:
    """conf/config.yaml (the defaults every job starts from) as a plain dict (interpolations kept)."""
    return copy.deepcopy(_load(os.path.join(CONF_DIR, "config.yaml")))


def names(group: str) -> list[str]:
    """Every config of the group (families, their presets, samplers), sorted."""
    folder = os.path.join(CONF_DIR, group)
    return sorted(f[:-5] for f in os.listdir(folder) if f.endswith(".yaml"))


def members(group: str, experiment: str) -> list[str]:
    """The configs of the group that join `experiment` (their YAML lists it under `experiments`)."""
    return [n for n in names(group) if experiment in (plugin_yaml(group, n).get(META_KEY) or {})]


def _declared(group: str, name: str, experiment: str) -> Any:
    """What config `name`'s YAML gives under experiments.<experiment> (None when it does not join)."""
    return (plugin_yaml(group, name).get(META_KEY) or {}).get(experiment)


def levels(group: str, name: str, experiment: str) -> dict[str, Any]:
    """{level: partial config} that config `name` declares for `experiment` ({} when it names none)."""
    return _level_table(group, f"conf/{group}/{name}.yaml", experiment, _declared(group, name, experiment))


def _level_table(group: str, label: str, experiment: str, table: Any) -> dict[str, Any]:
    """`table` as a dict, or, where it is {levels_of: other}, the table `other` itself declares there
    (label: where the table is, for the error message)."""
    table = dict(table or {})
    if LEVELS_OF not in table:
        return table
    other = table[LEVELS_OF]
    where = f"{label}: {META_KEY}.{experiment}.{LEVELS_OF}={other!r}"
    if len(table) > 1 or not isinstance(other, str):
        raise InputError(f"{where}: must be the entry's only key and name a {group} config")
    if other not in names(group):
        raise InputError(f"{where}: no such {group} config (available: {', '.join(names(group))})")
    found = dict(_declared(group, other, experiment) or {})
    if not found or LEVELS_OF in found:
        raise InputError(f"{where}: {other} declares no levels of its own for {experiment}")
    return found


def defaults(group: str, name: str) -> dict[str, Any]:
    """The plugin's config as its own YAML gives it, without the experiments part."""
    return {k: v for k, v in plugin_yaml(group, name).items() if k != META_KEY}


def model_defaults(name: str) -> dict[str, Any]:
    """A model config's complete defaults: its family's YAML overlaid by its own (a preset such as
    ddf_paper names its family and gives only what differs)."""
    own = defaults("model", name)
    return {**defaults("model", str(own.get(NAME_KEYS["model"], name))), **own}


def _check_types(label: str, given: Mapping[str, Any], default: Mapping[str, Any]) -> None:
    for key, value in given.items():
        ref = default[key]
        if isinstance(ref, Mapping):
            if not isinstance(value, Mapping):
                raise InputError(f"{label}.{key}={value!r}: must be a mapping with keys {', '.join(sorted(ref))}")
            strict_keys(f"{label}.{key}", value, ref)
            _check_types(f"{label}.{key}", value, ref)
        elif isinstance(ref, bool) and not isinstance(value, bool):
            raise InputError(f"{label}.{key}={value!r}: must be true or false")
        elif isinstance(ref, (int, float)) and not isinstance(ref, bool) and (
                isinstance(value, bool) or not isinstance(value, (int, float))):
            raise InputError(f"{label}.{key}={value!r}: must be a number")
        elif isinstance(ref, str) and not isinstance(value, str):
            raise InputError(f"{label}.{key}={value!r}: must be a string")


def strict_keys(label: str, given: Mapping[str, Any], known: Mapping[str, Any], near: bool = False) -> None:
    """One-line InputError naming the first unknown key of `given` (as label.key; the key alone for label "") and
    the known keys; with near, first the known names closest to it ("did you mean max_steps?")."""
    unknown = sorted(set(given) - set(known))
    if unknown:
        key, names = unknown[0], sorted(known)
        close = difflib.get_close_matches(key, names, n=3, cutoff=0.6) if near else []
        hint = f"did you mean {', '.join(close)}? " if close else ""
        raise InputError(f"{label + '.' if label else ''}{key}: unknown key ({hint}known: {', '.join(names)})")


def family_config(family: str, cfg: Mapping[str, Any]) -> dict[str, Any]:
    """The model config of `family`: conf/model/<family>.yaml overlaid by cfg, checked key by key.

    Unknown keys and values of the wrong type are a one-line InputError; a nested mapping (trace) is overlaid
    key by key; `family` and `experiments` are dropped (they say which module and which experiments, not how
    the model is built).
    """
    base = defaults("model", family)
    base.pop(NAME_KEYS["model"], None)
    given = {k: v for k, v in cfg.items() if k not in (NAME_KEYS["model"], META_KEY)}
    strict_keys("model", given, base)
    _check_types("model", given, base)
    return {**base, **{k: {**base[k], **v} if isinstance(base[k], Mapping) else v for k, v in given.items()}}


def _merge(into: dict[str, Any], part: Mapping[str, Any]) -> None:
    for key, value in part.items():
        if isinstance(value, Mapping) and isinstance(into.get(key), dict):
            _merge(into[key], value)
        else:
            into[key] = copy.deepcopy(value)


def job_config(cfg: Mapping[str, Any], choices: Mapping[str, str] | None = None) -> dict[str, Any]:
    """A resolved job config with the levels it asks for applied and the plugins' experiments parts dropped.

    For each group whose level key is set (cfg.capacity for the model, cfg.sample_size for the
    sampler), the group's `experiments.<experiment_name>.<level>` (a partial config of the whole job)
    is merged onto cfg. The record key is taken from what this returns. choices: Hydra's config-group
    choices ({"model": "ddf_tuned", ...}), so that an error names the YAML; else it names the family.
    """
    out = copy.deepcopy(dict(cfg))
    experiment = str(out.get("experiment_name"))
    parts = []
    for group, level_key in LEVEL_KEYS.items():
        node = out.get(group) or {}
        meta = node.pop(META_KEY, None) or {}
        level = out.get(level_key)
        if level is None:
            continue
        chosen = (choices or {}).get(group)
        label = f"conf/{group}/{chosen}.yaml" if chosen else f"{group} {node.get(NAME_KEYS[group])}"
        table = _level_table(group, label, experiment, meta.get(experiment))
        if level not in table:
            raise InputError(f"{level_key}={level}: {label} has no such level for experiment {experiment} "
                             f"(its levels: {', '.join(table) or 'none'})")
        parts.append(table[level] or {})
    for part in parts:
        _merge(out, part)
    return out


def _members_resolver(group: str, experiment: str) -> str:
    found = members(group, experiment)
    if not found:
        raise InputError(f"no conf/{group}/*.yaml joins experiment {experiment} (under `{META_KEY}`)")
    return ",".join(found)


if not OmegaConf.has_resolver("members"):
    OmegaConf.register_new_resolver("members", _members_resolver)
