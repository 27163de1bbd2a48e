"""`+experiment=tune`: each learned family's own search space, declared in its YAML, sampled by Optuna.

A model joins the tuning study by declaring `experiments.tune` in conf/model/<name>.yaml, one entry
per config path, each a single distribution:

    model.lr:    {log: [3.0e-4, 1.0e-2]}     float, log-uniform between the bounds
    model.delta: {float: [0.05, 0.2]}        float, uniform
    model.depth: {int: [3, 8]}               integer, uniform
    model.width: {choice: [64, 128, 256]}    one of the values

Hydra's Optuna sweeper (conf/experiment/tune.yaml: seeded TPE, the same trial count and fit seconds for
every family) calls `suggest` once per trial with the sweep's config, which names the model; each job
returns its record's `objective` metric (ddfbench.cli.task), so the study minimises the final chamfer
of a fixed wall-clock fit. An unchanged study re-proposes the same trials, so a rerun resumes from
the records.
"""

from __future__ import annotations

from typing import Any, Mapping

from ddfbench.core import plugins
from ddfbench.core.errors import InputError

EXPERIMENT = "tune"
KINDS = ("log", "float", "int", "choice")


def search_space(model: str) -> dict[str, tuple[str, list[Any]]]:
    """{config path: (kind, values)} that conf/model/<model>.yaml declares under `experiments.tune`.

    A malformed entry (unknown kind, bounds not increasing, a key the model does not have, or one a preset
    leaves to its family's YAML, which Hydra's override could not set) is a one-line InputError naming
    the file and the entry.
    """
    known, own = plugins.model_defaults(model), plugins.defaults("model", model)
    out: dict[str, tuple[str, list[Any]]] = {}
    for path, dist in plugins.levels("model", model, EXPERIMENT).items():
        where = f"conf/model/{model}.yaml: experiments.{EXPERIMENT}.{path}"
        if not (isinstance(dist, Mapping) and len(dist) == 1 and next(iter(dist)) in KINDS):
            raise InputError(f"{where}={dist!r}: must be one distribution {{kind: values}}, kind one of {', '.join(KINDS)}")
        kind, values = next(iter(dist.items()))
        values = list(values) if isinstance(values, (list, tuple)) else [values]
        if kind == "choice" and not values:
            raise InputError(f"{where}: choice needs at least one value")
        if kind != "choice" and (len(values) != 2 or not values[0] < values[1] or (kind == "log" and values[0] <= 0)):
            raise InputError(f"{where}: {kind} needs [low, high] with 0 {'<' if kind == 'log' else '<='} low < high, got {values}")
        group, _, key = str(path).partition(".")
        top = key.split(".")[0]
        if group != "model" or top not in known:
            raise InputError(f"{where}: not a key of the model (known: model.{', model.'.join(sorted(known))})")
        if top not in own:  # the sweeper's `model.<key>=` override cannot add a key to the preset
            raise InputError(f"{where}: the preset leaves it to its family's YAML, so the study's override cannot "
                             f"set it; give it in this file (e.g. {top}: {known[top]!r})")
        out[str(path)] = (kind, values)
    return out


def suggest(config: Any, trial: Any) -> None:
    """Optuna sweeper hook (hydra.sweeper.custom_search_space): draw the swept model's space into `trial`.

    config: the sweep's composed config (its hydra.runtime.choices.model names the model); trial: an
    optuna Trial. The sweeper turns trial.params into the job's overrides.
    """
    model = str(config.hydra.runtime.choices.model)
    space = search_space(model)
    if not space:
        raise InputError(f"model={model}: conf/model/{model}.yaml declares no experiments.{EXPERIMENT} search space "
                         f"(models that do: {', '.join(plugins.members('model', EXPERIMENT))})")
    for path, (kind, values) in space.items():
        if kind == "choice":
            trial.suggest_categorical(path, values)
        elif kind == "int":
            trial.suggest_int(path, int(values[0]), int(values[1]))
        else:
            trial.suggest_float(path, float(values[0]), float(values[1]), log=kind == "log")
